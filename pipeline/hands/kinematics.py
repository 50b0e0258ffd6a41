"""A hand as arrays: its kinematic tree, joint couplings and collision geometry, with forward
kinematics batched over many hand poses at once.

:func:`hand_model` turns a :class:`pipeline.hands.spec.Hand` and its URDF (:mod:`pipeline.hands.urdf`) into
a :class:`HandModel`:

- links in tree order (parents first; link 0 is the base, the palm), each with the joint that
  moves it. A joint is actuated (one of the hand's ``limits``), a ``<mimic>`` of an actuated
  joint (value = multiplier x leader + offset, as the URDF says; pybullet ignores mimic), or fixed;
- the closing motion: joint j moves by ``closing[j]`` x the finger's closing parameter, so a
  negative ratio closes toward the lower limit;
- ``lever[j, l]``: a bound on how far (m) any point of link l moves per unit of joint j, valid in
  every configuration (the chain's joint offsets plus the link's own reach, by the triangle
  inequality), so a closing step can be made that no point of any link outruns;
- collision geometry, in link frames: surface points (``points``, every corner and edge of a
  shape at ``spacing`` or finer, its faces at ``spacing``) for the link-to-mesh distance, and each
  shape's convex hull as planes and edges for the mesh-to-link distance and the inside test (a concave
  mesh shape counts as its hull there, as Bullet and MuJoCo treat a moving mesh); each shape's
  bounding box for drawing.
"""

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import ConvexHull, cKDTree
from scipy.spatial.transform import Rotation

from ..errors import BadParamsError
from ..tol import tol
from .urdf import read_urdf


@dataclass(frozen=True)
class HandModel:
    """See the module docstring. ``L`` links, ``J`` actuated joints, ``P`` surface points,
    ``K`` convex pieces, ``S`` drawn boxes."""

    name: str
    links: tuple  # (L,) link names
    parent: np.ndarray  # (L,) int, -1 for the base
    origin: np.ndarray  # (L, 4, 4) joint frame in the parent link frame
    axis: np.ndarray  # (L, 3) unit joint axes
    prismatic: np.ndarray  # (L,) bool
    driver: np.ndarray  # (L,) int, actuated joint moving the link's joint, -1 fixed
    multiplier: np.ndarray  # (L,)
    offset: np.ndarray  # (L,)
    joints: tuple  # (J,) actuated joint names, the hand's ``limits`` order
    lower: np.ndarray  # (J,)
    upper: np.ndarray  # (J,)
    closing: np.ndarray  # (J,) coupling ratio of the joint in its finger (sign = direction)
    finger: np.ndarray  # (J,) int, the finger of each joint
    moves: np.ndarray  # (J, L) bool, joint j moves link l
    lever: np.ndarray  # (J, L) m per unit of joint
    points: np.ndarray  # (P, 3) link frame
    point_link: np.ndarray  # (P,) sorted
    point_cover: np.ndarray  # (P,) sorted: the nearest cover sphere of the point's piece
    link_centre: np.ndarray  # (L, 3) link frame, centre of the link's bounding sphere
    link_radius: np.ndarray  # (L,) 0 for a link without geometry
    planes: np.ndarray  # (K, F, 4) unit outward normal and offset, n . x + d <= 0 inside; padded rows never bind
    piece_link: np.ndarray  # (K,)
    piece_edges: np.ndarray  # (K, E, 2, 3) link frame, NaN-padded: edges between non-coplanar faces
    edge_planes: np.ndarray  # (K, E, 2) the rows of ``planes`` of the two faces at each edge
    piece_centre: np.ndarray  # (K, 3)
    piece_radius: np.ndarray  # (K,)
    cover_centre: np.ndarray  # (C, 3) link frame: spheres covering the pieces, sorted by link
    cover_radius: np.ndarray  # (C,)
    cover_piece: np.ndarray  # (C,)
    cover_reach: np.ndarray  # (C,) farthest of its points (``point_cover``) from its centre; its radius if none
    link_cover_start: np.ndarray  # (L + 1,) each link's first cover sphere (covers are sorted by link), then C
    cover_point_start: np.ndarray  # (C + 1,) each cover sphere's first point (``point_cover`` order), then P
    box_centre: np.ndarray  # (S, 3) link frame
    box_rotation: np.ndarray  # (S, 3, 3)
    box_half: np.ndarray  # (S, 3)
    box_link: np.ndarray  # (S,)
    mimics: tuple  # ((joint name, link index), ...) joints that follow an actuated one

    @property
    def fingers(self):
        return int(self.finger.max()) + 1 if len(self.finger) else 0

    def joint_values(self, q):
        """{name: value} of every moving joint (mimics included) for actuated values ``q`` (J,)."""
        values = dict(zip(self.joints, map(float, q)))
        for name, link in self.mimics:
            values[name] = float(self.multiplier[link] * q[self.driver[link]] + self.offset[link])
        return values


def link_poses(model, base, q):
    """World poses of every link.

    Parameters
    ----------
    model : HandModel
    base : (n, 4, 4) float
        The base link's pose in the object frame (metres).
    q : (n, J) float
        Actuated joint values (rad or m).

    Returns
    -------
    (n, L, 4, 4) float64
    """
    return _link_poses(
        np.ascontiguousarray(base, np.float64),
        np.ascontiguousarray(q, np.float64),
        model.parent,
        model.origin,
        model.driver,
        model.multiplier,
        model.offset,
        model.prismatic,
        model.axis,
    )


@njit(cache=True)
def _link_poses(base, q, parent, origin, driver, multiplier, offset, prismatic, axis):
    """See :func:`link_poses`: links in tree order (a parent before its children)."""
    count, links = len(q), len(parent)
    poses = np.empty((count, links, 4, 4))
    frame = np.empty((4, 4))
    # Rodrigues: R = I + sin(angle) K + (1 - cos(angle)) K K, K the axis' cross-product matrix
    cross = np.zeros((links, 3, 3))
    for link in range(links):
        x, y, z = axis[link]
        cross[link, 0, 1], cross[link, 0, 2], cross[link, 1, 2] = -z, y, -x
        cross[link, 1, 0], cross[link, 2, 0], cross[link, 2, 1] = z, -y, x
    square = np.zeros((links, 3, 3))
    for link in range(links):
        for i in range(3):
            for j in range(3):
                for k in range(3):
                    square[link, i, j] += cross[link, i, k] * cross[link, k, j]
    for row in range(count):
        poses[row, 0] = base[row]
        for link in range(1, links):
            above = poses[row, parent[link]]
            for i in range(4):
                for j in range(4):
                    frame[i, j] = (
                        above[i, 0] * origin[link, 0, j]
                        + above[i, 1] * origin[link, 1, j]
                        + above[i, 2] * origin[link, 2, j]
                        + above[i, 3] * origin[link, 3, j]
                    )
            pose = poses[row, link]
            pose[:, :] = frame
            if driver[link] < 0:
                continue
            value = q[row, driver[link]] * multiplier[link] + offset[link]
            if prismatic[link]:
                for i in range(3):
                    pose[i, 3] += value * (
                        frame[i, 0] * axis[link, 0] + frame[i, 1] * axis[link, 1] + frame[i, 2] * axis[link, 2]
                    )
                continue
            sin, cos = np.sin(value), np.cos(value)
            for i in range(3):
                for j in range(3):
                    total = 0.0
                    for k in range(3):
                        turn = ((1.0 if k == j else 0.0) + sin * cross[link, k, j]) + (1.0 - cos) * square[link, k, j]
                        total += frame[i, k] * turn
                    pose[i, j] = total
    return poses


def transform(poses, owner, local):
    """World positions (m, 3) of link-frame points ``local`` (m, 3), point i carried by the pose
    ``poses[owner[i]]`` ((n, 4, 4) poses, flat index ``owner``)."""
    return _transform(
        np.ascontiguousarray(poses, np.float64),
        np.ascontiguousarray(owner, np.int64),
        np.ascontiguousarray(local, np.float64).reshape(-1, 3),
    )


@njit(cache=True)
def _transform(poses, owner, local):
    world = np.empty((len(owner), 3))
    for point in range(len(owner)):
        carry(poses[owner[point]], local[point], world[point])
    return world


def point_velocities(model, poses, rows, links, points, active):
    """(t, 3) velocity (m per unit of closing) of the world ``points`` (t, 3) on the ``links``
    (t,) of the poses ``rows`` (t,) ((n, L, 4, 4) ``poses``) under the joints ``active`` (t, J)
    closing: each joint between the link and the base adds its coupling ratio times its axis
    (prismatic) or its axis crossed with the point's arm from the joint (revolute)."""
    return _point_velocities(
        np.ascontiguousarray(poses, np.float64),
        np.ascontiguousarray(rows, np.int64),
        np.ascontiguousarray(links, np.int64),
        np.ascontiguousarray(points, np.float64).reshape(-1, 3),
        np.ascontiguousarray(active, np.bool_),
        model.parent,
        model.driver,
        model.closing,
        model.multiplier,
        model.prismatic,
        model.axis,
    )


@njit(cache=True)
def _point_velocities(poses, rows, links, points, active, parent, driver, closing, multiplier, prismatic, axis):
    """See :func:`point_velocities`; each float the one of the numpy expressions it replaced
    (a closing pass's few touching points paid 0.09 ms of numpy calls)."""
    velocity = np.zeros((len(links), 3))
    turn, arm = np.empty(3), np.empty(3)
    for touch in range(len(links)):
        link = links[touch]
        while link > 0:
            joint = driver[link]
            if joint >= 0:
                rate = closing[joint] * multiplier[link] * (1.0 if active[touch, joint] else 0.0)
                frame = poses[rows[touch], link]
                for row in range(3):
                    turn[row] = (
                        frame[row, 0] * axis[link, 0] + frame[row, 1] * axis[link, 1] + frame[row, 2] * axis[link, 2]
                    )
                if not prismatic[link]:
                    for row in range(3):
                        arm[row] = points[touch, row] - frame[row, 3]
                    x = turn[1] * arm[2] - turn[2] * arm[1]
                    y = turn[2] * arm[0] - turn[0] * arm[2]
                    z = turn[0] * arm[1] - turn[1] * arm[0]
                    turn[0], turn[1], turn[2] = x, y, z
                for row in range(3):
                    velocity[touch, row] += rate * turn[row]
            link = parent[link]
    return velocity


@njit(cache=True)
def carry(pose, local, world):
    """Write into ``world`` (3,) the link-frame point ``local`` (3,) carried by ``pose`` (4, 4):
    the one rounding of every kernel that moves link points (compiled code calls it per point)."""
    for row in range(3):
        world[row] = (pose[row, 0] * local[0] + pose[row, 1] * local[1] + pose[row, 2] * local[2]) + pose[row, 3]


def _edge_points(vertices, edges, spacing, refine=1):
    """Points along each edge (e, 2) of ``vertices`` (v, 3), ends included, at most ``spacing``
    apart, each gap then split in ``refine`` (so the points at ``refine`` 1 are among them)."""
    starts, ends = vertices[edges[:, 0]], vertices[edges[:, 1]]
    counts = refine * np.maximum(np.ceil(np.linalg.norm(ends - starts, axis=1) / spacing).astype(int), 1)
    owner = np.repeat(np.arange(len(edges)), counts + 1)
    fraction = np.concatenate([np.linspace(0.0, 1.0, count + 1) for count in counts])
    points = starts[owner] + fraction[:, None] * (ends - starts)[owner]
    return np.unique(np.round(points, tol.point_decimals), axis=0)


def _shape_mesh(shape):
    """(vertices, faces) of a non-box collision shape in its own frame."""
    import trimesh

    if shape.kind == "sphere":
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=shape.size[0])
    elif shape.kind == "cylinder":
        mesh = trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[1], sections=24)
    elif shape.kind == "capsule":
        mesh = trimesh.creation.capsule(height=shape.size[1], radius=shape.size[0], count=(12, 12))
    else:
        try:
            mesh = trimesh.load(shape.mesh, force="mesh")
        except Exception as err:  # noqa: BLE001 - trimesh raises many types for a bad file
            raise BadParamsError(f"{shape.mesh}: collision mesh cannot be read ({err})") from None
        if not len(getattr(mesh, "faces", ())):
            raise BadParamsError(f"{shape.mesh}: collision mesh has no triangles")
        mesh.apply_scale(shape.size)
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def _shape_points_and_hull(shape, spacing, refine=1):
    """Points (m, 3) on the edges of a shape (its corners and edges at ``spacing``, split
    ``refine`` times: :func:`_edge_points`) and its hull vertices (h, 3), in its link frame.

    Faces need no points: the distance from an object corner to a link face is the mesh-to-link
    side's, and an object edge or face is nearest a flat link face on the face's boundary."""
    if shape.kind == "box":
        half = np.asarray(shape.size) / 2
        hull = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1], indexing="ij")).reshape(3, -1).T * half
        edges = np.array(
            [(a, b) for a in range(8) for b in range(a + 1, 8) if np.count_nonzero(hull[a] != hull[b]) == 1]
        )
        local = _edge_points(hull, edges, spacing, refine)
    else:
        import trimesh

        vertices, faces = _shape_mesh(shape)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        # the mesh's feature edges: flat faces' inner triangulation edges carry no contact
        sharp = mesh.face_adjacency_edges[mesh.face_adjacency_angles > np.radians(1.0)]
        boundary = trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)
        edges = np.concatenate([sharp, mesh.edges_sorted[boundary]]) if len(boundary) else sharp
        local = np.concatenate([_edge_points(vertices, edges, spacing, refine), vertices]) if len(edges) else vertices
        local = np.unique(np.round(local, tol.point_decimals), axis=0)
        hull = vertices
    rotation, translation = shape.pose[:3, :3], shape.pose[:3, 3]
    return local @ rotation.T + translation, hull @ rotation.T + translation


def nearest_centre(points, centres):
    """(n,) index of the nearest of (c, 3) ``centres`` to each of (n, 3) ``points``, the first in
    ``centres`` order among equally near ones: ``argmin`` of the (n, c) distance table, bit for
    bit, without the table (a hand with mesh links has thousands of points and covers)."""
    tree = cKDTree(centres)
    nearest, _ = tree.query(points)
    # the tree's distances may differ from numpy's in the last bits: every centre within a hair
    # of the nearest is measured again as the table would, and the first of the least wins
    found = tree.query_ball_point(points, nearest * (1 + 1e-9) + 1e-12)
    owner = np.repeat(np.arange(len(points)), [len(near) for near in found])
    candidate = np.concatenate(found).astype(np.int64) if len(owner) else np.zeros(0, np.int64)
    gaps = np.linalg.norm(points[owner] - centres[candidate], axis=1)
    order = np.lexsort((candidate, gaps, owner))
    first = np.searchsorted(owner[order], np.arange(len(points)))
    return candidate[order][first]


def _cover(hull, planes):
    """Spheres (centres (c, 3), radii (c,)) covering the convex piece with vertices ``hull`` and
    ``planes``: near-cubic cells of at most :attr:`pipeline.tol.Tolerances.cover_cell_m` over its
    box, those that meet the piece."""
    cell = tol.cover_cell_m
    low, high = hull.min(axis=0), hull.max(axis=0)
    counts = np.maximum(np.ceil((high - low) / cell - 1e-9).astype(int), 1)
    size = (high - low) / counts
    axes = [low[k] + (np.arange(counts[k]) + 0.5) * size[k] for k in range(3)]
    centres = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    radius = np.linalg.norm(size) / 2
    meets = (centres @ planes[:, :3].T + planes[:, 3]).max(axis=1) <= radius
    return centres[meets], np.full(meets.sum(), radius)


def _planes(hull_points):
    """(f, 4) outward unit planes of the convex hull of (h, 3) points."""
    hull = ConvexHull(hull_points)
    equations = np.unique(np.round(hull.equations, tol.plane_decimals), axis=0)
    return equations


def _hull_edges(hull_points, planes):
    """(e, 2, 3) the convex hull's edges between faces that are not coplanar, and (e, 2) the
    rows of ``planes`` (from :func:`_planes`) of the two faces at each."""
    hull = ConvexHull(hull_points)
    owner = {}
    for facet, simplex in enumerate(hull.simplices):
        for corner in range(3):
            edge = tuple(sorted((simplex[corner], simplex[(corner + 1) % 3])))
            owner.setdefault(edge, []).append(facet)
    edges = [
        (edge, facets)
        for edge, facets in owner.items()
        if len(facets) == 2
        and not np.allclose(hull.equations[facets[0]], hull.equations[facets[1]], atol=10.0**-tol.plane_decimals)
    ]
    ends = np.array([edge for edge, _ in edges], dtype=np.int64).reshape(-1, 2)
    sides = np.array(
        [
            [
                np.abs(planes - np.round(hull.equations[facet], tol.plane_decimals)).sum(axis=1).argmin()
                for facet in facets
            ]
            for _, facets in edges
        ],
        dtype=np.int64,
    ).reshape(-1, 2)
    return hull.points[ends], sides


@functools.lru_cache(maxsize=16)
def _cached_model(key, hand, spacing, refine):
    return _build(hand, spacing, refine)


def hand_model(hand, *, spacing=0.003, refine=1):
    """The :class:`HandModel` of ``hand`` (cached per hand, spacing and refinement).

    Parameters
    ----------
    hand : pipeline.hands.spec.Hand
    spacing : float
        Largest distance (m) between neighbouring surface points of a collision shape.
    refine : int
        Each gap between those points split in this many (the trial's contact model: its
        points are the closing model's and more between them, so a link that the closing
        rule finds within the tolerance is still found so). Only ``points`` and their covers
        differ from the model at ``refine`` 1.
    """
    return _cached_model(hand.key(), _Frozen(hand), float(spacing), int(refine))


class _Frozen:
    """Wraps an unhashable Hand for the cache (the key decides equality)."""

    def __init__(self, hand):
        self.hand = hand

    def __hash__(self):
        return hash(self.hand.key())

    def __eq__(self, other):
        return self.hand.key() == other.hand.key()


def _build(frozen, spacing, refine):
    hand = frozen.hand
    robot = read_robot(hand)
    links = (robot.root,) + tuple(joint.child for joint in robot.joints)
    index = {name: number for number, name in enumerate(links)}
    actuated = tuple(hand.limits)
    by_name = {joint.name: joint for joint in robot.joints}
    count = len(links)
    parent, origin = np.full(count, -1), np.tile(np.eye(4), (count, 1, 1))
    axis, prismatic = np.zeros((count, 3)), np.zeros(count, bool)
    driver, multiplier, offset = np.full(count, -1), np.ones(count), np.zeros(count)
    mimics = []
    for joint in robot.joints:
        link = index[joint.child]
        parent[link], origin[link], axis[link] = index[joint.parent], joint.origin, joint.axis
        prismatic[link] = joint.kind == "prismatic"
        if joint.kind == "fixed":
            continue
        if joint.name in actuated:
            driver[link] = actuated.index(joint.name)
        elif joint.mimic is not None and joint.mimic[0] in actuated:
            driver[link], multiplier[link], offset[link] = actuated.index(joint.mimic[0]), *joint.mimic[1:]
            mimics.append((joint.name, link))
        # any other joint stays at 0: a joint the hand does not declare does not move
    missing = [name for name in actuated if name not in by_name]
    if missing:
        raise BadParamsError(f"hand {hand.name}: joint {missing[0]!r} is not in its URDF")
    closing, finger_of = np.zeros(len(actuated)), np.full(len(actuated), -1)
    for number, finger in enumerate(hand.fingers):
        for joint, ratio in zip(finger.joints, finger.ratios):
            closing[actuated.index(joint)], finger_of[actuated.index(joint)] = ratio, number
    lower = np.array([hand.limits[name][0] for name in actuated])
    upper = np.array([hand.limits[name][1] for name in actuated])
    # geometry
    points, point_link, pieces, piece_link, piece_points, boxes = [], [], [], [], [], []
    for name in links:
        for shape in robot.shapes[name]:
            local, hull = _shape_points_and_hull(shape, spacing, refine)
            points.append(local)
            point_link.append(np.full(len(local), index[name]))
            piece_points.append(len(local))
            pieces.append(hull)
            piece_link.append(index[name])
            if shape.kind == "box":
                boxes.append((shape.pose[:3, 3], shape.pose[:3, :3], np.asarray(shape.size) / 2, index[name]))
            else:  # drawn as its bounding box in the link frame
                low, high = hull.min(axis=0), hull.max(axis=0)
                boxes.append(((low + high) / 2, np.eye(3), (high - low) / 2, index[name]))
    points = np.concatenate(points) if points else np.zeros((0, 3))
    point_link = np.concatenate(point_link) if point_link else np.zeros(0, int)
    link_centre, link_radius = np.zeros((count, 3)), np.zeros(count)
    for link in range(count):
        own = points[point_link == link]
        if len(own):
            link_centre[link] = (own.min(axis=0) + own.max(axis=0)) / 2
            link_radius[link] = np.linalg.norm(own - link_centre[link], axis=1).max()
    planes = [_planes(hull) for hull in pieces]
    width = max((len(p) for p in planes), default=1)
    padded = np.zeros((len(planes), width, 4))
    padded[..., 3] = -np.inf  # a padded plane never holds the maximum
    for number, equations in enumerate(planes):
        padded[number, : len(equations)] = equations
    edges = [_hull_edges(hull, equations) for hull, equations in zip(pieces, planes)]
    edge_width = max((len(e[0]) for e in edges), default=1)
    piece_edges = np.full((len(edges), edge_width, 2, 3), np.nan)  # padded edges are never nearest
    edge_planes = np.zeros((len(edges), edge_width, 2), np.int64)
    for number, (segments, sides) in enumerate(edges):
        piece_edges[number, : len(segments)] = segments
        edge_planes[number, : len(sides)] = sides
    piece_centre = np.array([(h.min(axis=0) + h.max(axis=0)) / 2 for h in pieces]).reshape(-1, 3)
    piece_radius = np.array([np.linalg.norm(h - c, axis=1).max() for h, c in zip(pieces, piece_centre)])
    covers = [_cover(hull, equations) for hull, equations in zip(pieces, planes)]
    cover_piece = (
        np.concatenate([np.full(len(c[0]), k) for k, c in enumerate(covers)]).astype(int)
        if covers
        else np.zeros(0, int)
    )
    cover_centre = np.concatenate([c[0] for c in covers]).reshape(-1, 3) if covers else np.zeros((0, 3))
    # each point joins the nearest cover sphere of its piece, so that a measure can skip the
    # points of a sphere that is far from the object (points stay sorted by link: covers are)
    point_cover = np.zeros(len(points), int)
    piece_start = np.searchsorted(cover_piece, np.arange(len(pieces) + 1))
    for piece, rows in enumerate(np.split(np.arange(len(points)), np.cumsum(piece_points)[:-1])):
        point_cover[rows] = piece_start[piece] + nearest_centre(
            points[rows], cover_centre[piece_start[piece] : piece_start[piece + 1]]
        )
    order = np.argsort(point_cover, kind="stable")
    points, point_link, point_cover = points[order], point_link[order], point_cover[order]
    cover_reach = np.zeros(len(cover_centre))
    np.maximum.at(cover_reach, point_cover, np.linalg.norm(points - cover_centre[point_cover], axis=1))
    covered = np.zeros(len(cover_centre), bool)
    covered[point_cover] = True
    cover_radius = np.concatenate([c[1] for c in covers]) if covers else np.zeros(0)
    cover_reach[~covered] = cover_radius[~covered]
    # levers: per actuated joint and link, a bound on point speed valid in every configuration
    reach = np.linalg.norm(origin[:, :3, 3], axis=1)  # distance between consecutive joint frames
    own_reach = np.array(
        [
            np.linalg.norm(points[point_link == link], axis=1).max() if (point_link == link).any() else 0.0
            for link in range(count)
        ]
    )
    moves, lever = np.zeros((len(actuated), count), bool), np.zeros((len(actuated), count))
    for link in range(count):
        chain, walk = [], link
        while walk > 0:
            chain.append(walk)
            walk = parent[walk]
        for position, joint_link in enumerate(chain):  # chain[0] = link itself, then its ancestors
            if driver[joint_link] < 0:
                continue
            arm = 1.0 if prismatic[joint_link] else reach[chain[:position]].sum() + own_reach[link]
            moves[driver[joint_link], link] = True
            lever[driver[joint_link], link] += abs(multiplier[joint_link]) * arm
    return HandModel(
        hand.name,
        links,
        parent,
        origin,
        axis,
        prismatic,
        driver,
        multiplier,
        offset,
        actuated,
        lower,
        upper,
        closing,
        finger_of,
        moves,
        lever,
        points,
        point_link,
        point_cover,
        link_centre,
        link_radius,
        padded,
        np.array(piece_link, int),
        piece_edges,
        edge_planes,
        piece_centre,
        piece_radius,
        cover_centre,
        cover_radius,
        cover_piece,
        cover_reach,
        np.searchsorted(np.array(piece_link, int)[cover_piece], np.arange(len(links) + 1)),
        np.searchsorted(point_cover, np.arange(len(cover_centre) + 1)),
        np.array([box[0] for box in boxes]).reshape(-1, 3),
        np.array([box[1] for box in boxes]).reshape(-1, 3, 3),
        np.array([box[2] for box in boxes]).reshape(-1, 3),
        np.array([box[3] for box in boxes], int),
        tuple(mimics),
    )


def base_poses(hand, grasp, approach, orient):
    """(n, 4, 4) base poses that put the hand's grasp centre at ``grasp`` (n, 3), its approach
    axis along ``approach`` and its wrap axis along ``orient`` (n, 3, unit; ``orient`` is made
    orthogonal to ``approach``)."""
    hand_axes = np.column_stack([hand.approach, hand.wrap, np.cross(hand.approach, hand.wrap)])
    orient = orient - np.einsum("ij,ij->i", orient, approach)[:, None] * approach
    orient = orient / np.linalg.norm(orient, axis=1, keepdims=True)
    world_axes = np.stack([approach, orient, np.cross(approach, orient)], axis=2)
    rotation = world_axes @ hand_axes.T
    poses = np.tile(np.eye(4), (len(grasp), 1, 1))
    poses[:, :3, :3] = rotation
    poses[:, :3, 3] = grasp - rotation @ np.asarray(hand.grasp_centre, float)
    return poses


def hand_boxes(model, base_positions, base_orientations, joints):
    """Every collision shape's drawing box of the hands ``model`` with their URDF bases at
    ``base_positions`` (n, 3) m and ``base_orientations`` (n, 4) quaternions x y z w, and
    ``joints`` (n, J) in ``model.joints`` order: world centres (n, S, 3), rotations
    (n, S, 3, 3) and half extents (S, 3)."""
    base = np.tile(np.eye(4), (len(base_positions), 1, 1))
    if len(base):
        base[:, :3, :3] = Rotation.from_quat(base_orientations).as_matrix()
    base[:, :3, 3] = base_positions
    poses = link_poses(model, base, np.asarray(joints, np.float64).reshape(len(base), len(model.joints)))
    poses = poses[:, model.box_link]
    centres = np.einsum("nsij,sj->nsi", poses[..., :3, :3], model.box_centre) + poses[..., :3, 3]
    return centres, poses[..., :3, :3] @ model.box_rotation, model.box_half


def open_gap(hand, preshape=None):
    """The open hand's finger gap around its grasp centre, from its links' drawing boxes in
    ``preshape`` (None: the default), in the palm frame's axes.

    Returns
    -------
    (lo, hi, half_width, reach) in metres, or None where the fingers are not on both sides of
    the grasp centre: along the closing axis approach x wrap, the inner faces of the finger
    links on either side (lo < hi, from the grasp centre); the finger links' half extent along
    the wrap axis; how far past the grasp centre they reach along the approach. The gap is
    measured between the finger links level with the grasp centre along the approach, where
    there are such links on both sides.
    """
    model = hand_model(hand)
    joints = np.array([[hand.preshape(preshape)[joint] for joint in model.joints]])
    centres, rotations, half = hand_boxes(model, np.zeros((1, 3)), np.array([[0.0, 0.0, 0.0, 1.0]]), joints)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    corners = centres[0][:, None, :] + np.einsum("sij,scj->sci", rotations[0], signs[None] * half[:, None, :])
    finger = model.box_link != 0  # link 0 is the palm
    relative = corners[finger] - np.asarray(hand.grasp_centre, float)
    approach, wrap = np.asarray(hand.approach, float), np.asarray(hand.wrap, float)
    across, along, ahead = relative @ np.cross(approach, wrap), relative @ wrap, relative @ approach
    side = np.sign(across.mean(axis=1))
    # the gap where the object is held: between the finger links level with the grasp centre
    # (a thumb's base nearer the palm's middle does not narrow it), or any where none is
    level = (ahead.min(axis=1) <= 0) & (ahead.max(axis=1) >= 0)
    if (level & (side > 0)).any() and (level & (side < 0)).any():
        side = np.where(level, side, 0.0)
    if not ((side > 0).any() and (side < 0).any()):
        return None
    lo, hi = across[side < 0].max(), across[side > 0].min()
    return float(lo), float(hi), float(np.abs(along).max()), float(ahead.max())


def read_robot(hand):
    """The hand's URDF tree (its file, or a built-in's generated text)."""
    from .spec import urdf_text

    if hand.urdf is None:
        return read_urdf(f"<built-in {hand.name}>", text=urdf_text(hand))
    return read_urdf(hand.urdf, base_link=hand.base_link)

"""Contact regions (pipeline.contacts): GraspIt's hull corners, known on flat and line patches,
and a choice that depends on the touching points, not on their order or repeats."""

import numpy as np

from pipeline.contacts import region_corners

UP = np.array([0.0, 0.0, 1.0])


def pad(count=5, half=0.01):
    """A count x count grid of touching points on a 2 half x 2 half face, normal +z."""
    axis = np.linspace(-half, half, count)
    points = np.array([(x, y, 0.0) for x in axis for y in axis])
    return points, np.tile(UP, (len(points), 1))


def as_set(points):
    return {tuple(np.round(point, 9)) for point in points}


def test_a_face_contact_is_its_four_corners():
    points, normals = pad()
    corners = points[region_corners(points, normals)]
    assert as_set(corners) == {(x, y, 0.0) for x in (-0.01, 0.01) for y in (-0.01, 0.01)}


def test_a_line_contact_is_its_two_ends():
    points = np.c_[np.linspace(0.0, 0.02, 9), np.zeros(9), np.zeros(9)]
    corners = points[region_corners(points, np.tile(UP, (9, 1)))]
    assert as_set(corners) == {(0.0, 0.0, 0.0), (0.02, 0.0, 0.0)}


def test_a_smoothly_curved_patch_is_one_region():
    """Normals 2 deg apart along an arc of 40 deg: each agrees with its neighbours within 5 deg,
    so the chain is one region and gives its two ends, though the ends differ by 40 deg."""
    angle = np.radians(np.arange(0, 41, 2))
    normals = np.c_[np.sin(angle), np.zeros_like(angle), np.cos(angle)]
    points = 0.05 * normals
    assert list(region_corners(points, normals, max_corners=4)) == [0, len(angle) - 1]


def test_two_faces_give_the_corners_of_each_and_at_most_max_corners():
    points, normals = pad()
    side = np.c_[np.full(len(points), 0.02), points[:, 0], points[:, 1] + 0.02]
    both = np.r_[points, side]
    outward = np.r_[normals, np.tile([1.0, 0.0, 0.0], (len(side), 1))]
    assert len(region_corners(both, outward, max_corners=8)) == 8
    kept = region_corners(both, outward, max_corners=4)
    assert len(kept) == 4 and {tuple(n) for n in outward[kept]} == {(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)}


def test_order_and_repeats_do_not_change_the_corners(rng):
    """The measure may find a touching point twice (two overlapping cover spheres) and in any
    order; the region's corners, and which max_corners of them are kept, must not change."""
    points, normals = pad()
    side = np.c_[np.full(len(points), 0.02), points[:, 0], points[:, 1] + 0.02]
    both = np.r_[points, side]
    outward = np.r_[normals, np.tile([1.0, 0.0, 0.0], (len(side), 1))]
    expected = as_set(both[region_corners(both, outward, max_corners=4)])
    for _ in range(5):
        order = rng.permutation(np.r_[np.arange(len(both)), rng.integers(0, len(both), 20)])
        assert as_set(both[order][region_corners(both[order], outward[order], max_corners=4)]) == expected


def test_a_cap_never_keeps_a_corner_twice():
    """Corners sharing a position (two normals at one point) are distinct contacts: a cap
    larger than the number of positions keeps each once."""
    points = np.array([(0, 0, 0), (0.01, 0, 0), (0, 0, 0), (0.01, 0, 0), (0.005, 0, 0)], float)
    normals = np.array([(0, 0, 1), (0, 0, 1), (0, 1, 0), (0, 1, 0), (0, 0.6, 0.8)], float)
    kept = region_corners(points, normals, max_corners=4)
    assert len(set(kept.tolist())) == 4


def test_a_scattered_face_contact_is_its_convex_hull(rng):
    """Touching points scattered on a tilted face: the corners are exactly the vertices of their
    2D convex hull (Qhull's, computed independently in the face's own coordinates)."""
    from scipy.spatial import ConvexHull

    normal = np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9])
    first = np.cross(normal, [1.0, 0.0, 0.0])
    first /= np.linalg.norm(first)
    second = np.cross(normal, first)
    for _ in range(5):
        flat = rng.uniform(-0.01, 0.01, (40, 2))
        points = 0.05 * normal + flat[:, :1] * first + flat[:, 1:] * second
        corners = region_corners(points, np.tile(normal, (len(points), 1)))
        assert corners.tolist() == sorted(ConvexHull(flat).vertices.tolist())

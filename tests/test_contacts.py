"""Contact regions (pipeline.trial.contacts): GraspIt's hull corners, known on flat and line patches,
and a choice that depends on the touching points, not on their order or repeats."""

import numpy as np

from pipeline.trial.contacts import region_corners

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


def test_a_curved_patch_is_cut_into_regions_within_the_angle_of_a_seed():
    """Normals 2 deg apart along an arc of 40 deg, each touched once: the seeds go from the
    smallest normal (x, lexicographically) up, each region takes the normals within 5 deg of
    its seed (0..-4.. are 1 region: 0, 2, 4 deg; then 6, 8, 10; ...), and gives its two ends:
    the arc's normals survive in steps of at most 5 deg instead of one chain of 40 deg."""
    angle = np.radians(np.arange(0, 41, 2))
    normals = np.c_[np.sin(angle), np.zeros_like(angle), np.cos(angle)]
    points = 0.05 * normals
    kept = np.degrees(angle[region_corners(points, normals)]).round().astype(int).tolist()
    assert kept == [0, 4, 6, 10, 12, 16, 18, 22, 24, 28, 30, 34, 36, 40]


def test_a_finger_along_a_round_leg_keeps_the_legs_facet_normals():
    """A finger face (normal -y reversed: +y outward) lying along a leg of 4 deg facets: many
    touching points with the finger's normal and a strip of points on each facet. A chain of
    agreeing normals made one region whose hull kept only the finger's normal; seeded regions
    keep a corner on each side of the 5 deg band around it."""
    along = np.linspace(0.0, 0.02, 11)
    face = np.array([(0.0, 0.0, z) for z in along] * 3) + np.repeat([[-0.005, 0, 0], [0, 0, 0], [0.005, 0, 0]], 11, 0)
    face_normals = np.tile([0.0, 1.0, 0.0], (len(face), 1))
    # the leg's strip lies inside the finger face's footprint, so one region's hull is the face's
    facets = np.radians(np.arange(-16, 17, 4))
    strip = np.array([(0.01 * np.sin(a), 0.0, z) for a in facets for z in (0.005, 0.015)])
    strip_normals = np.repeat(np.c_[np.sin(facets), np.cos(facets), np.zeros_like(facets)], 2, axis=0)
    points, normals = np.r_[face, strip], np.r_[face_normals, strip_normals]
    kept = normals[region_corners(points, normals)]
    tilt = np.degrees(np.arctan2(kept[:, 0], kept[:, 1])).round().astype(int)
    assert tilt.min() == -16 and tilt.max() == 16


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


def unit(vector):
    vector = np.asarray(vector, float)
    return vector / np.linalg.norm(vector)


def test_a_normal_inside_its_features_cone_is_kept_and_one_outside_goes_to_the_rim():
    """clamp_to_cone, known answers: a vertex's cone of 45 deg around +z; an edge along +z whose
    faces' normals are +-1.875 deg about +x (a 96-gon's)."""
    from pipeline.geometry.mesh_query import clamp_to_cone

    half = np.radians(45.0)
    inside, outside = unit([np.sin(np.radians(30)), 0, np.cos(np.radians(30))]), unit([0, np.sin(1.0), np.cos(1.0)])
    kept, moved = clamp_to_cone(np.array([inside, outside]), np.tile(UP, (2, 1)), np.full(2, half), np.zeros((2, 3)))
    assert np.allclose(kept, inside)
    assert np.allclose(moved, [0.0, np.sin(half), np.cos(half)])  # 45 deg from +z, toward the normal
    # a link face tilted 35 deg about the edge and 20 deg along it: the arc's end nearest it
    facet = np.radians(1.875)
    tilted = unit([np.cos(np.radians(35)), np.sin(np.radians(35)), np.tan(np.radians(20))])
    (clamped,) = clamp_to_cone(tilted[None], np.array([[1.0, 0, 0]]), np.array([facet]), np.array([UP]))
    assert np.allclose(clamped, [np.cos(facet), np.sin(facet), 0.0])


def test_normal_cones_of_a_96_gon_cylinder():
    """A cylinder of 96 sides: each side edge's cone is half its 3.75 deg; the faces' neighbours
    are trimesh's face adjacency; a point on a side edge clamps to within 1.875 deg of radial."""
    import trimesh

    from pipeline.geometry.mesh_query import ObjectMesh

    cylinder = trimesh.creation.cylinder(radius=0.05, height=0.1, sections=96)
    mesh = ObjectMesh(cylinder.vertices, cylinder.faces)
    pairs = {tuple(sorted((face, other))) for face, row in enumerate(mesh.cones.neighbours) for other in row}
    assert pairs == set(map(tuple, np.sort(cylinder.face_adjacency, axis=1)))
    side = np.abs(mesh.features.edges[:, 2]) > 0.99  # the vertical edges' points
    assert side.any() and np.allclose(np.degrees(mesh.features.half_angles[side]), 1.875, atol=1e-6)
    # a link face normal 35 deg off the radial at the middle of a side edge
    rim = cylinder.vertices[np.hypot(cylinder.vertices[:, 0], cylinder.vertices[:, 1]) > 0.04]
    corner = rim[np.argmin(np.abs(rim[:, 1] - 0.01))]
    point = np.array([corner[0], corner[1], 0.0])
    found = mesh.closest(point[None] * 1.01)
    assert mesh.on_border(found).all()
    link_face = unit([np.cos(np.radians(35)), np.sin(np.radians(35)), 0.0])[None]
    (normal,) = mesh.clamp_on_border(link_face, found)
    radial = unit([point[0], point[1], 0.0])
    assert np.degrees(np.arccos(np.clip(normal @ radial, -1, 1))) <= 1.875 + 1e-6


def test_a_pickled_object_mesh_answers_as_the_original_whatever_its_threads():
    """The trial workers get the caller's mesh pickled (its grid as it is, open3d's scene rebuilt):
    the same grid and the same exact answers, known on a 10 cm cube, with one thread or all."""
    import pickle

    import trimesh

    from pipeline.geometry.mesh_query import ObjectMesh

    box = trimesh.creation.box(extents=(0.1, 0.1, 0.1))
    mesh = ObjectMesh(box.vertices, box.faces)
    copy = pickle.loads(pickle.dumps(mesh))
    copy.threads = 1
    assert np.array_equal(copy.grid, mesh.grid) and copy.scene is not mesh.scene
    points = np.array([[0.0, 0.0, 0.0], [0.08, 0.0, 0.0], [0.0, 0.03, 0.0], [0.06, 0.06, 0.0]])
    for query in (mesh, copy):
        np.testing.assert_allclose(query.signed_distance(points), [-0.05, 0.03, -0.02, np.hypot(0.01, 0.01)], atol=1e-7)
        assert query.inside(points).tolist() == [True, False, True, False]
        np.testing.assert_allclose(query.exit_distance(points[:1], [[0.0, 0.0, 1.0]]), [0.05], atol=1e-7)
    found, again = mesh.closest(points), copy.closest(points)
    assert np.array_equal(found.points, again.points) and np.array_equal(found.triangles, again.triangles)

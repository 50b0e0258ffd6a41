"""The slow reference of the trial engine (:mod:`pipeline.trial.reference`): its exact geometry
against known answers, so that its agreement with the engine measures the engine."""

import numpy as np
import pytest

from pipeline.hands.kinematics import base_poses
from pipeline.hands.spec import HANDS
from pipeline.trial.reference import ReferenceEngine, _hull_gap, closest_on_triangles
from test_simulation import cube, surface
from test_trial_engine import random_candidates

UNIT_TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@pytest.mark.parametrize(
    "point, expected",
    [
        ((0.2, 0.3, 1.0), (0.2, 0.3, 0.0)),  # above the face
        ((-1.0, -2.0, 0.5), (0.0, 0.0, 0.0)),  # past corner a
        ((3.0, -0.5, 0.0), (1.0, 0.0, 0.0)),  # past corner b
        ((-0.1, 2.0, -1.0), (0.0, 1.0, 0.0)),  # past corner c
        ((0.4, -1.0, 2.0), (0.4, 0.0, 0.0)),  # off edge ab
        ((-3.0, 0.7, 0.0), (0.0, 0.7, 0.0)),  # off edge ac
        ((1.0, 1.0, 0.25), (0.5, 0.5, 0.0)),  # off edge bc
    ],
)
def test_closest_point_on_a_triangle_in_each_voronoi_region(point, expected):
    found, border = closest_on_triangles(np.array([point]), UNIT_TRIANGLE[None])
    np.testing.assert_allclose(found[0], expected, atol=1e-15)
    assert border[0] == (expected != (0.2, 0.3, 0.0))


def test_closest_points_on_random_triangles_are_never_beaten_by_a_dense_grid():
    rng = np.random.default_rng(0)
    triangles, points = rng.normal(size=(100, 3, 3)), 2 * rng.normal(size=(100, 3))
    found = np.linalg.norm(closest_on_triangles(points, triangles)[0] - points, axis=1)
    weights = np.array([(i, j) for i in range(101) for j in range(101 - i)]) / 100
    for triangle, point, distance in zip(triangles, points, found):
        grid = triangle[0] + weights @ (triangle[1:] - triangle[0])
        nearest = np.linalg.norm(grid - point, axis=1).min()
        assert distance <= nearest + 1e-12 and distance >= nearest - 0.02


def test_hull_gap_of_a_cube_inside_off_a_face_and_off_an_edge():
    """A 1 m cube (half 0.5): 0.4 m inside through +x; 0.3 m off the +x face; off the edge
    x = y = 0.5 at sqrt(0.02) m, the face whose normal agrees with ``facing``."""
    from scipy.spatial import ConvexHull

    corners = np.array(np.meshgrid([-0.5, 0.5], [-0.5, 0.5], [-0.5, 0.5], indexing="ij")).reshape(3, -1).T
    hull = ConvexHull(corners)
    triangles, planes = hull.points[hull.simplices], hull.equations
    points = np.array([[0.1, 0.0, 0.0], [0.8, 0.1, -0.2], [0.6, 0.6, 0.0], [0.6, 0.6, 0.0]])
    facing = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.9, 0.1, 0.0], [0.1, 0.9, 0.0]])
    gap, face = _hull_gap(triangles, planes, points, facing)
    np.testing.assert_allclose(gap, [-0.4, 0.3, np.sqrt(0.02), np.sqrt(0.02)], atol=1e-12)
    np.testing.assert_allclose(planes[face, :3], [[1, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]], atol=1e-12)


@pytest.mark.parametrize("name", ["parallel_jaw", "armar3"])
def test_reference_distances_of_every_link_match_its_brute_force_pairs(name):
    """Random hand poses near a box: pybullet's distance of every link (its shapes queried as
    bodies of their own, margin 0) against the nearest of the reference's touching pairs (link
    points every 0.5 mm to the object's triangles, the object's features to the link's hull):
    never longer, at most 0.05 mm shorter (two sampled edges crossing, from 1 mm). Queried
    through the URDF's links, pybullet kept the importer's 1 mm margin on child links and read
    up to 0.73 mm long."""
    box = surface("primitive:box", extents=(0.05, 0.03, 0.04))
    hand = HANDS[name]
    reference = ReferenceEngine(box, hand)
    model = reference.model
    grasp, approach, orient = random_candidates(box, 8, np.random.default_rng(2))
    base = base_poses(hand, grasp, approach, orient)
    base[:, :3, 3] -= 0.01 * approach  # most links a few mm to cm off the box
    compared = 0
    for pose in base:
        reference._pose(pose, np.array([hand.preshape(None)[joint] for joint in model.joints]))
        for link in np.flatnonzero(model.link_radius > 0):
            theirs = reference._gap(link)
            if 0.001 <= theirs <= 0.02:
                brute = reference._touching_pairs(link, theirs + 1e-4)[0].min()
                assert brute - 5e-5 <= theirs <= brute + 1e-9, (model.links[link], theirs, brute)
                compared += 1
    reference.close()
    assert compared >= 10


def test_reference_jaw_squeezing_a_cube_gets_the_pads_face_contacts():
    """The jaw across a 4 cm cube (closing along x, the 20 mm pads stopping 1 mm off the
    faces), placed clear and come on until its palm is within the 2 mm tolerance of the top
    face: force closure; the palm's contacts lie on the top face (z = 2 cm, normal +z); the
    pads' contacts with a face's normal lie on that face (x = +-2 cm),
    from z = -2 to 2 cm and in y as far as the cube's edges stay within the 2 mm tolerance of
    the pad's edge, 10 + sqrt(2^2 - 1^2) = 11.73 mm (less the 0.5 mm sampling of the edges);
    every other contact lies on the cube's top or bottom edge, where the pads' edges pass
    within the tolerance of it (with the face there that the pad's edge lies most off)."""
    reference = ReferenceEngine(cube(), HANDS["parallel_jaw"])
    result = reference.trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0])
    reference.close()
    assert result.outcome == "force_closure" and set(result.touched) == {"palm", "left_pad", "right_pad"}
    # the open palm starts 5 mm above the top and stops within the tolerance: 3 mm on, or 4 mm
    # where pybullet's float32 distance puts the 2 mm gap a hair above the tolerance
    assert -0.004 - 1e-9 <= result.retract_m <= -0.003 + 1e-9
    np.testing.assert_allclose(result.joint_positions, 0.019, atol=1e-6)
    # the palm's contacts, all with normal +z: on the top face, or on the cube's vertical edges
    # within the tolerance below it (a sharp edge takes the palm face's normal)
    palm = result.contact_links == 0
    np.testing.assert_allclose(result.contact_normals[palm], [[0.0, 0.0, 1.0]] * palm.sum(), atol=1e-9)
    heights = result.contact_points[palm, 2]
    assert heights.max() == pytest.approx(0.02, abs=1e-12) and heights.min() >= 0.02 - 0.002 - 1e-12
    points, normals = result.contact_points[~palm], result.contact_normals[~palm]
    on_face = np.abs(normals[:, 0]) > 1 - 1e-9
    for side in (1.0, -1.0):
        face = points[on_face & (np.sign(normals[:, 0]) == side)]
        np.testing.assert_allclose(face[:, 0], side * 0.02, atol=1e-12)
        # from the bottom edge to within 1 mm of the top one (the pads' tops meet the palm,
        # which rests on the top face; the edges sampled every 0.5 mm)
        assert face[:, 2].min() == pytest.approx(-0.02, abs=1e-12) and 0.019 - 1e-12 <= face[:, 2].max() <= 0.02
        reach = 0.01 + np.sqrt(0.002**2 - 0.001**2)
        assert reach - 5e-4 <= -face[:, 1].min() <= reach and reach - 5e-4 <= face[:, 1].max() <= reach
    np.testing.assert_allclose(np.abs(points[~on_face][:, [0, 2]]), 0.02, atol=1e-12)


@pytest.mark.parametrize("name", sorted(HANDS))
def test_reference_point_velocities_match_the_engines_kinematics(name):
    """Random closing states of every hand: the velocity of points on each moving link, from
    pybullet's joint frames and axes (the reference) and from the engine's own kinematics
    (:func:`pipeline.hands.kinematics.point_velocities`), agree to 1e-5 of the speed
    (pybullet's frames are float32: the numerical derivative the reference used before was off
    by 2e-4, which pressed a jaw pad sliding past a vertex beside its side face)."""
    from pipeline.hands.kinematics import link_poses, point_velocities
    from pipeline.trial.engine import GraspEngine

    box = surface("primitive:box", extents=(0.05, 0.03, 0.04))
    hand, rng = HANDS[name], np.random.default_rng(5)
    reference, engine = ReferenceEngine(box, hand), GraspEngine(box, hand)
    model = engine.model
    grasp, approach, orient = random_candidates(box, 4, rng)
    compared = 0
    for base in base_poses(hand, grasp, approach, orient):
        q = model.lower + (model.upper - model.lower) * rng.random(len(model.joints))
        active = (rng.random(len(model.joints)) < 0.7) & (model.closing != 0)  # Barrett's spread stays
        poses = link_poses(model, base[None], q[None])
        reference._pose(base, q)
        for link in np.flatnonzero(model.moves[active].any(axis=0) & (model.link_radius > 0)):
            points = poses[0, link, :3, 3] + rng.normal(0.0, 0.02, (5, 3))
            theirs = reference._velocity(link, points, active)
            ours = point_velocities(model, poses, np.zeros(5, int), np.full(5, link), points, np.tile(active, (5, 1)))
            speed = np.linalg.norm(ours, axis=1, keepdims=True)
            assert (speed > 0).all()
            np.testing.assert_allclose(theirs / speed, ours / speed, atol=1e-5)
            compared += 1
    reference.close()
    assert compared >= 4

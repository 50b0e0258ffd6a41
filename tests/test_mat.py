"""Medial spheres of analytic shapes against their known medial axes (paper II, Fig. 1)."""

import numpy as np
import pytest

from conftest import chain
from pipeline.geometry.mat import nearest_samples, object_angle, reconstruct

DEG = np.pi / 180


def test_box_interior_spheres_are_half_thickness_and_flat_angle():
    # 0.10 x 0.06 x 0.02 box: the medial sheet far from the edges is z = 0, radius 0.01
    spheres = chain("box")["mat"]
    centre = spheres.centers
    far = (np.abs(centre[:, 0]) < 0.03) & (np.abs(centre[:, 1]) < 0.01)
    assert far.sum() > 500
    assert spheres.object_angle[far].min() > 170 * DEG
    assert np.abs(spheres.radii[far] / 0.01 - 1).max() < 0.01


def test_box_edge_spheres_are_near_90_degrees():
    # spheres equidistant from two faces and well away from the third sit on an edge's
    # bisector sheet: the two contacts are 90 degrees apart seen from the centre (Fig. 1c)
    spheres = chain("box")["mat"]
    face_distance = np.sort(np.array([0.05, 0.03, 0.01]) - np.abs(spheres.centers), axis=1)
    edge = (face_distance[:, 1] - face_distance[:, 0] < 2e-4) & (face_distance[:, 2] - face_distance[:, 1] > 3e-3)
    edge &= spheres.radii < 0.008
    assert edge.sum() > 500
    assert np.median(np.abs(spheres.object_angle[edge] - 90 * DEG)) < 10 * DEG


@pytest.mark.parametrize("name, radius, half_length", [("capsule", 0.02, 0.05), ("cylinder", 0.025, 0.06)])
def test_tube_spheres_lie_on_the_axis(name, radius, half_length):
    spheres = chain(name)["mat"]
    centre = spheres.centers
    body = np.abs(centre[:, 2]) < half_length - radius
    # the reduced set (paper III-A) of the tube's body is exactly the axis
    reduced = body & (spheres.object_angle >= 120 * DEG)
    assert reduced.sum() > 50
    assert np.hypot(centre[reduced, 0], centre[reduced, 1]).max() < 0.01 * radius
    assert np.abs(spheres.radii[reduced] / radius - 1).max() < 0.01
    # and the spheres on the axis see their contacts (a ring) at wide angles
    on_axis = body & (np.hypot(centre[:, 0], centre[:, 1]) < 0.01 * radius)
    assert np.percentile(spheres.object_angle[on_axis], 5) > 150 * DEG
    assert np.median(spheres.object_angle[on_axis]) > 170 * DEG


def test_sphere_collapses_to_its_centre():
    spheres = chain("sphere")["mat"]
    assert np.linalg.norm(spheres.centers, axis=1).max() < 0.05 * 0.04
    assert np.abs(spheres.radii / 0.04 - 1).max() < 0.03
    assert spheres.object_angle.max() > 170 * DEG


def test_plate_medial_surface_is_the_mid_plane():
    # 6 mm plate: the sampling gaps (spacing ~0.5 mm at 60k samples) bound the accuracy
    spheres = chain("plate", count=60000)["mat"]
    centre = spheres.centers
    inner = (spheres.object_angle >= 120 * DEG) & (np.abs(centre[:, :2]).max(axis=1) < 0.04)
    assert inner.sum() > 1000
    assert np.median(np.abs(centre[inner, 2])) < 0.01 * 0.003
    assert np.percentile(np.abs(centre[inner, 2]), 99) < 0.03 * 0.003
    assert np.percentile(np.abs(spheres.radii[inner] / 0.003 - 1), 99) < 0.03


def test_torus_centres_lie_on_the_core_circle():
    spheres = chain("torus")["mat"]
    kept = spheres.object_angle >= 120 * DEG
    assert kept.sum() > 500
    centre = spheres.centers[kept]
    off_core = np.hypot(np.hypot(centre[:, 0], centre[:, 1]) - 0.05, centre[:, 2])
    assert off_core.max() < 0.01 * 0.012
    assert np.abs(spheres.radii[kept] / 0.012 - 1).max() < 0.01


def test_grid_search_gives_the_kdtree_answer():
    artefacts = chain("capsule", count=5000)
    surface, axis = artefacts["sample"], artefacts["medial_axis"]
    # the k nearest distances agree (the float32 kd-tree may break exact ties differently)
    by_tree = nearest_samples(surface.points, axis.centers, count=8, search="kdtree", kdtree_eps=0.0)[0]
    by_grid = nearest_samples(surface.points, axis.centers, count=8, search="grid")[0]
    np.testing.assert_allclose(by_grid, by_tree, rtol=1e-6)
    spheres_tree = reconstruct(surface, axis, search="kdtree", kdtree_eps=0.0)
    spheres_grid = reconstruct(surface, axis, search="grid")
    np.testing.assert_array_equal(spheres_grid.radii, spheres_tree.radii)
    assert np.mean(np.abs(spheres_grid.object_angle - spheres_tree.object_angle) < 1e-6) > 0.99


def test_object_angle_by_hand():
    # contacts at +x, +y and -x seen from the origin: widest pair is +x/-x, 180 degrees
    points = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0]])
    angles = object_angle(np.zeros((2, 3)), points, np.array([[0, 1, -1], [0, 1, 2]]))
    np.testing.assert_allclose(angles, [np.pi / 2, np.pi])


def test_reconstruct_is_deterministic_and_leaves_inputs_alone():
    artefacts = chain("box", count=3000)
    surface, axis = artefacts["sample"], artefacts["medial_axis"]
    before = surface.points.copy()
    first = reconstruct(surface, axis)
    second = reconstruct(surface, axis)
    assert np.array_equal(first.centers, second.centers) and first.key == second.key
    assert np.array_equal(surface.points, before)


def test_contacts_touch_within_tau():
    artefacts = chain("box", count=5000)
    spheres = reconstruct(artefacts["sample"], artefacts["medial_axis"], tau=0.01)
    rows, cols = np.nonzero(spheres.contacts >= 0)
    distance = np.linalg.norm(artefacts["sample"].points[spheres.contacts[rows, cols]] - spheres.centers[rows], axis=1)
    assert (distance <= spheres.radii[rows] * 1.01 + 1e-15).all()
    assert (distance >= spheres.radii[rows] - 1e-15).all()


def test_balls_centred_outside_the_object_are_dropped():
    # a ball the approximate growing pass left at its start radius lies beside the object (seen on
    # the thin-walled vase); a medial ball's centre is behind the outward normal of its nearest sample
    from pipeline.geometry.medial_axis import inner_balls

    directions = np.random.default_rng(0).normal(size=(2000, 3))
    normals = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    points = 0.04 * normals
    centers = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.03], [0.0, 0.0, 0.09], [0.05, 0.0, 0.0]])
    assert inner_balls(points, normals, centers).tolist() == [True, True, False, False]
    assert chain("sphere")["medial_axis"].radii.max() < 0.041  # no start-radius ball survives

"""Surface samples: on the surface, area-uniform, crease-aware normals, seeded."""

import numpy as np
import pytest
import trimesh

from pipeline.geometry.sampling import corner_normals, estimate_cloud_normals, sample_mesh


def test_box_samples_lie_on_faces_with_exact_face_normals(rng):
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.02])
    points, normals, _ = sample_mesh(box.vertices, box.faces, 20000, rng=rng, sharp_angle=np.radians(30))
    half = np.array([0.05, 0.03, 0.01])
    # every sample is on a face: one coordinate at +-half, normal = that axis (sharp edges)
    on_face = np.isclose(np.abs(points), half, atol=1e-12)
    assert np.all(on_face.sum(axis=1) >= 1)
    axis = np.argmax(np.abs(normals), axis=1)
    assert np.allclose(np.abs(normals[np.arange(len(normals)), axis]), 1.0)
    assert np.all(on_face[np.arange(len(points)), axis])
    # area-uniform: share of samples per face pair within 4 sigma of the area share
    areas = np.array([0.06 * 0.02, 0.1 * 0.02, 0.1 * 0.06])
    share = np.bincount(axis, minlength=3) / len(points)
    expected = areas / areas.sum()
    assert np.all(np.abs(share - expected) < 4 * np.sqrt(expected * (1 - expected) / len(points)))


def test_cylinder_side_normals_are_radial_and_caps_stay_flat(rng):
    cylinder = trimesh.creation.cylinder(radius=0.02, height=0.1, sections=64)
    points, normals, _ = sample_mesh(cylinder.vertices, cylinder.faces, 20000, rng=rng, sharp_angle=np.radians(30))
    side = np.abs(points[:, 2]) < 0.05 - 1e-9
    radial = points[side] * [1, 1, 0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    # interpolated smooth normals: radial to 1e-6 rad (face normals would be off by up to pi/64)
    assert np.degrees(np.arccos(np.clip((normals[side] * radial).sum(1), -1, 1))).max() < 1e-4
    np.testing.assert_allclose(np.abs(normals[~side, 2]), 1.0)


def test_cube_corner_normals_are_face_normals():
    cube = trimesh.creation.box()
    corners = corner_normals(cube.vertices, cube.faces, sharp_angle=np.radians(30))
    np.testing.assert_allclose(corners, np.repeat(cube.face_normals[:, None, :], 3, axis=1), atol=1e-12)


def test_sampling_is_seeded_and_leaves_mesh_alone():
    box = trimesh.creation.box(extents=[0.1, 0.06, 0.02])
    vertices = box.vertices.copy()
    first = sample_mesh(box.vertices, box.faces, 500, rng=np.random.default_rng(3), sharp_angle=0.5)
    again = sample_mesh(box.vertices, box.faces, 500, rng=np.random.default_rng(3), sharp_angle=0.5)
    other = sample_mesh(box.vertices, box.faces, 500, rng=np.random.default_rng(4), sharp_angle=0.5)
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    assert not np.array_equal(first[0], other[0])
    assert np.array_equal(box.vertices, vertices)


@pytest.mark.parametrize("radius", [0.03, 1.0])
def test_cloud_normals_point_outward(radius, rng):
    direction = rng.standard_normal((3000, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    normals = estimate_cloud_normals(radius * direction, neighbours=20)
    assert np.all((normals * direction).sum(axis=1) > 0.95)

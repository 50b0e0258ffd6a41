"""The expanding polytope's distance from the origin to a hull's boundary, against answers known
analytically (boxes) or from Qhull's whole hull."""

import itertools

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from pipeline.trial.expanding_hull import nearest_facet
from pipeline.trial.quality import contact_wrenches


def whole_hull_distance(points):
    """Signed distance from the origin to the nearest facet of Qhull's hull (positive inside)."""
    return -ConvexHull(points).equations[:, -1].max()


@pytest.mark.parametrize("dimension", [3, 6])
def test_box_corners_give_the_distance_to_the_nearest_face(dimension, rng):
    """A box [-h, h] around c: the origin is min_i (h_i - |c_i|) from its boundary. Its faces hold
    2 ** (d - 1) coplanar corners each (32 in 6D), the hardest case for a hull without merging."""
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=dimension)))
    for _ in range(10):
        half = rng.uniform(0.5, 2.0, dimension)
        centre = rng.uniform(-0.4, 0.4, dimension)
        distance = nearest_facet(corners * half + centre)
        assert distance == pytest.approx(np.min(half - np.abs(centre)), abs=1e-12)


def test_general_points_match_qhulls_whole_hull(rng):
    """Gaussian points in 6D, the origin inside or outside: inside, the same distance as Qhull's;
    outside, a value at most 1e-12 (the search stops at a separating support)."""
    inside = outside = 0
    for _ in range(40):
        points = rng.normal(size=(rng.integers(10, 200), 6)) + rng.normal(scale=0.8, size=6)
        exact = whole_hull_distance(points)
        found = nearest_facet(points)
        if exact > 0:
            assert found == pytest.approx(exact, abs=1e-12)
            inside += 1
        else:
            assert found <= 1e-12
            outside += 1
    assert inside > 5 and outside > 5  # both cases exercised


def test_grasp_wrenches_match_qhull(rng):
    """Friction-cone wrenches of random grasps (8 coplanar cone edges per contact, the engine's
    input): the same distance as Qhull's whole hull."""
    for _ in range(20):
        outward = rng.normal(size=(rng.integers(3, 15), 3))
        outward /= np.linalg.norm(outward, axis=1, keepdims=True)
        wrenches = contact_wrenches(0.03 * outward, -outward, mu=0.5, torque_scale=0.03).reshape(-1, 6)
        exact = whole_hull_distance(wrenches)
        assert nearest_facet(wrenches) == pytest.approx(exact, abs=1e-12) if exact > 0 else nearest_facet(wrenches) <= 0


def test_flat_or_too_few_points_are_refused(rng):
    """Points in a hyperplane have no 6D hull: None, for the caller to decide (not a guess)."""
    flat = np.c_[rng.normal(size=(50, 5)), np.zeros(50)]
    assert nearest_facet(flat) is None
    assert nearest_facet(rng.normal(size=(6, 6))) is None  # 6 points span at most 5 dimensions


def test_inputs_not_modified_and_deterministic(rng):
    points = rng.normal(size=(80, 6))
    before = points.copy()
    assert nearest_facet(points) == nearest_facet(points.copy())
    np.testing.assert_array_equal(points, before)

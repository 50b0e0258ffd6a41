"""Symmetry classes and candidate grasps against known answers (paper III, Fig. 8, Fig. 10)."""

import functools

import numpy as np
import pytest

from conftest import chain
from pipeline.arrays import vectors
from pipeline.geometry.candidates import IDS_PER_SPHERE, generate, generate_for_hands
from pipeline.geometry.symmetry import AXIS, INTERIOR, ISOLATED, RIM, cell_moments, classify, neighbourhood_pca
from pipeline.hands.spec import HANDS, Hand, get_hand
from pipeline.params import Params, SampleParams
from pipeline.plan import run_chain

ARMAR3 = get_hand("armar3")


@functools.lru_cache(maxsize=None)
def planned(source, scale=1.0):
    artefacts, _ = run_chain(source, Params(sample=SampleParams(count=20000)), scale=scale, seed=7, hands=["armar3"])
    return artefacts


@pytest.mark.parametrize("name", ["capsule", "cylinder"])
def test_tube_spheres_are_axes_with_orthogonal_approaches(name):
    symmetry = classify(chain(name)["sphere_grid"])
    radius = {"capsule": 0.02, "cylinder": 0.025}[name]
    body = np.abs(symmetry.centers[:, 2]) < {"capsule": 0.05, "cylinder": 0.06}[name] - radius
    assert body.sum() > 100 and (symmetry.class_id[body] == AXIS).all()
    table = generate(symmetry, ARMAR3)
    on_body = np.isin(table.sphere_index, symmetry.sphere_index[body])
    approach, orient = vectors(table, "approach")[on_body], vectors(table, "orient")[on_body]
    z = np.array([0.0, 0.0, 1.0])
    assert len(approach) == 8 * body.sum()  # 4 directions x flipped orientation (Simox)
    # P_o = +-e1 and P_d orthogonal to it; e1 is the true axis to within 0.1 degree
    assert np.abs((approach * orient).sum(axis=1)).max() < 1e-6
    assert np.degrees(np.arccos(np.abs(orient @ z))).max() < 0.1
    assert np.abs(approach @ z).max() < np.sin(np.radians(0.1))
    np.testing.assert_allclose(np.linalg.norm(approach, axis=1), 1.0)


def test_plate_border_is_rim_middle_is_interior():
    symmetry = classify(chain("plate")["sphere_grid"])
    # the medial sheet of the 6 mm plate ends ~3 mm inside the plate's edge
    xy = np.abs(symmetry.centers[:, :2])
    middle = xy.max(axis=1) < 0.03
    assert middle.sum() > 1000 and (symmetry.class_id[middle] == INTERIOR).all()
    # the mid-plane sheet of the 6 mm plate ends ~3 mm inside the edge (x or y ~ 0.047); along
    # an edge, away from the corners (a quarter-disc neighbourhood reads as a plane) and off
    # the Y-junction spheres of the edge, the outermost spheres see a half disc: rho ~ 0.28
    on_sheet = (np.abs(symmetry.centers[:, 2]) < 5e-4) & (xy.min(axis=1) < 0.035)
    reach = xy[on_sheet].max(axis=1)
    outermost = reach > np.percentile(reach, 99.5) - 5e-4
    assert outermost.sum() > 50
    assert np.mean(symmetry.class_id[on_sheet][outermost] == RIM) > 0.7
    # and rims only near the border: within half a search radius of the sheet's end
    rim_reach = reach[symmetry.class_id[on_sheet] == RIM]
    assert rim_reach.min() > reach.max() - symmetry.search_radius / 2
    table = generate(symmetry, ARMAR3)
    assert not np.isin(table.sphere_index, symmetry.sphere_index[symmetry.class_id == INTERIOR]).any()
    rim = table[table.sphere_class == "rim"]
    assert len(rim) > 50
    # inward: the approach points toward the plate's centre (the origin) in the plate's plane
    inward = -vectors(rim, "grasp")[:, :2]
    assert ((vectors(rim, "approach")[:, :2] * inward).sum(axis=1) > 0).all()


def test_solid_sphere_is_isolated_with_six_approaches():
    symmetry = classify(chain("sphere")["sphere_grid"])
    assert len(symmetry) >= 1 and (symmetry.class_id == ISOLATED).all()
    table = generate(symmetry, ARMAR3)  # medial spheres ~7.9 cm across: under 9.4 cm
    assert (table.groupby("sphere_index").size() == 12).all()  # +-x, +-y, +-z, each with P_o flipped
    approach = {tuple(row) for row in np.round(vectors(table, "approach"), 12)}
    assert approach == {tuple(row) for row in np.vstack([np.eye(3), -np.eye(3)])}
    assert np.abs((vectors(table, "approach") * vectors(table, "orient")).sum(axis=1)).max() == 0


def test_spheres_wider_than_the_hand_get_no_candidate():
    symmetry = classify(chain("sphere")["sphere_grid"])
    diameter = 2 * symmetry.radii
    assert 0.075 < diameter.min() and diameter.max() < 0.081
    assert len(generate(symmetry, Hand("narrow", 0.075))) == 0
    assert len(generate(symmetry, Hand("wide", 0.081))) == 12 * len(symmetry)


def test_no_sphere_in_the_reduced_set_gives_no_class_and_no_candidate():
    # a bumpy ball (pybullet's soccer ball) has no sphere of object angle >= 120 deg: stages go on, empty
    symmetry = classify(chain("box")["sphere_grid"], min_diameter_m=1.0)
    assert len(symmetry) == 0 and symmetry.axes.shape == (0, 9)
    assert len(generate_for_hands(symmetry, None, [ARMAR3, get_hand("barrett")])) == 0


def test_candidate_ids_are_stable_and_unique():
    symmetry = classify(chain("capsule", count=5000)["sphere_grid"])
    table = generate_for_hands(symmetry, None, [ARMAR3, HANDS["barrett"]])
    assert not table.duplicated(["hand", "id"]).any()
    assert ((table.id // IDS_PER_SPHERE) == table.sphere_index).all()
    again = generate_for_hands(symmetry, None, [ARMAR3, HANDS["barrett"]])
    assert table.equals(again)


def test_cell_pca_is_exact_per_cell_and_matches_by_hand():
    # four points on a line and one off it; one cell each (fraction 0): the PCA of all five
    points = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0], [1.5, 1, 0]], float)
    values, axes, cog, members = neighbourhood_pca(points[:1], 10.0, *cell_moments(points, 0.0)[:3])
    expected = np.linalg.eigvalsh(np.cov(points.T, bias=True))[::-1]
    np.testing.assert_allclose(values[0], expected, atol=1e-12)
    np.testing.assert_allclose(cog[0], points.mean(axis=0))
    assert members[0] == 5 and abs(axes[0, 0] @ [1, 0, 0]) > 0.99
    # the same five points in one coarse cell give the same moments
    coarse = neighbourhood_pca(points[:1], 10.0, *cell_moments(points, 100.0)[:3])
    np.testing.assert_allclose(coarse[0], values, atol=1e-12)


def test_cell_and_exact_analysis_agree():
    grid = chain("box")["sphere_grid"]
    fast, exact = classify(grid), classify(grid, pca_cell_fraction=0.0)
    assert np.mean(fast.class_id == exact.class_id) > 0.95

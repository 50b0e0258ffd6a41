"""Report figures: colours, the sphere figure (paper Fig. 5) and grasp pictures (paper Fig. 7)."""

import dataclasses
import functools

import numpy as np
import pandas as pd
import pytest

from conftest import chain
from pipeline.arrays import vectors
from pipeline.errors import BadInputError
from pipeline.geometry.sampling import sample_object
from pipeline.hands.spec import HANDS
from pipeline.outputs.figures import (
    CLASS_COLOURS,
    best_grasps,
    candidate_lines,
    diameter_colours,
    grasp_images,
    image_grid,
    sphere_figure,
)
from pipeline.outputs.render import render_hand
from pipeline.params import SampleParams
from pipeline.trial.protocol import simulate

BARRETT = HANDS["barrett"]


@functools.lru_cache(maxsize=None)
def cylinder_chain():
    """Sample -> candidates of the 5 cm x 12 cm cylinder (axis spheres on the body, varied spheres at the caps)."""
    return chain("cylinder", count=3000)


@functools.lru_cache(maxsize=None)
def cylinder_trials():
    """Two Barrett trials on the 5 cm cylinder, approached orthogonally to its axis: both force
    closure (tests/test_simulation.py checks six such approaches)."""
    surface = sample_object(
        "primitive:cylinder",
        scale=1.0,
        shape=dict(radius=0.025, height=0.12),
        rng=np.random.default_rng(5),
        source_key="cylinder",
        **dataclasses.asdict(SampleParams()),
    )
    rows = [
        {
            "hand": "barrett",
            "id": k,
            "sphere_index": 0,
            "sphere_class": "axis",
            "diameter_m": 0.05,
            "preshape": "parallel",
            "grasp_x": 0.0,
            "grasp_y": 0.0,
            "grasp_z": 0.01,
            "approach_x": np.cos(angle),
            "approach_y": np.sin(angle),
            "approach_z": 0.0,
            "orient_x": 0.0,
            "orient_y": 0.0,
            "orient_z": 1.0,
        }
        for k, angle in enumerate((0.0, 2.0))
    ]
    trials, _ = simulate(surface, pd.DataFrame(rows), [BARRETT], spheres_per_object=1, baseline_trials=0, seed=1)
    assert (trials.outcome == "force_closure").all()
    return surface, trials


def colour_mask(image, rgb, tolerance=40):
    return (np.abs(image.astype(int) - np.asarray(rgb, int)) <= tolerance).all(axis=2)


# -- diameter_colours ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "diameters, expected",
    [
        ([0.01, 0.02, 0.03], [[1, 0, 0], [0, 1, 0], [0, 0, 1]]),  # min red, midpoint green, max blue
        ([0.03, 0.015, 0.01, 0.025], [[0, 0, 1], [0.5, 0.5, 0], [1, 0, 0], [0, 0.5, 0.5]]),  # linear in between
        ([0.02, 0.02], [[0, 1, 0], [0, 1, 0]]),  # constant: all green, no division by 0
        ([0.07], [[0, 1, 0]]),
    ],
)
def test_diameter_colours_known_answers(diameters, expected):
    values = np.array(diameters)
    before = values.copy()
    colours = diameter_colours(values)
    np.testing.assert_allclose(colours, expected, atol=1e-12)
    assert colours.shape == (len(values), 3) and colours.dtype == np.float64
    np.testing.assert_array_equal(values, before)  # input not modified


def test_diameter_colours_rejects_bad_input_and_accepts_empty():
    assert diameter_colours(np.zeros(0)).shape == (0, 3)
    with pytest.raises(BadInputError, match=r"diameters: expected shape \(n,\), got \(2, 2\)"):
        diameter_colours(np.ones((2, 2)))
    with pytest.raises(BadInputError, match="NaN"):
        diameter_colours([0.01, np.nan])


# -- candidate lines and the sphere figure ---------------------------------------------------


def test_candidate_lines_one_line_per_approach_starting_at_the_grasp_target():
    artefacts = cylinder_chain()
    symmetry, candidates = artefacts["classify"], artefacts["candidates"]
    mine = candidates[candidates.hand == "armar3"]
    segments, kinds, drawn = candidate_lines(symmetry, mine, length=0.01, max_lines=10**9)
    spheres = mine.sphere_index.nunique()
    assert drawn == spheres and (kinds == "e1").sum() == spheres == (kinds == "e2").sum()
    approach = ~np.isin(kinds, ["e1", "e2", "orient"])
    # flipped candidates (P_o -> -P_o) share their approach line: half as many lines as candidates
    assert approach.sum() == len(mine) // 2 == (kinds == "orient").sum()
    for name in ("axis", "rim", "pair", "isolated"):
        assert (kinds == name).sum() == (mine.sphere_class == name).sum() // 2
    lengths = np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1)
    np.testing.assert_allclose(lengths[approach], 0.01)
    np.testing.assert_allclose(lengths[np.isin(kinds, ["e1", "e2"])], 0.005)
    np.testing.assert_allclose(lengths[kinds == "orient"], 0.0025)
    # an approach line starts at a candidate's P_g and runs back along -P_d
    start, direction = segments[approach, 0], (segments[approach, 0] - segments[approach, 1]) / 0.01
    table = np.column_stack([vectors(mine, "grasp"), vectors(mine, "approach")])
    lines = np.column_stack([start, direction])
    assert all(np.abs(table - line).max(axis=1).min() < 1e-12 for line in lines)


def test_candidate_lines_stay_within_the_budget_and_follow_the_seed():
    artefacts = cylinder_chain()
    mine = artefacts["candidates"][artefacts["candidates"].hand == "armar3"]
    segments, kinds, drawn = candidate_lines(artefacts["classify"], mine, length=0.01, max_lines=200, seed=3)
    assert 150 < len(segments) <= 200 and drawn < mine.sphere_index.nunique()
    again = candidate_lines(artefacts["classify"], mine, length=0.01, max_lines=200, seed=3)
    np.testing.assert_array_equal(segments, again[0])
    other = candidate_lines(artefacts["classify"], mine, length=0.01, max_lines=200, seed=4)
    assert not np.array_equal(np.sort(segments.reshape(-1)), np.sort(other[0].reshape(-1)))


def test_candidate_lines_reject_candidates_of_another_sphere_set():
    artefacts = cylinder_chain()
    stray = artefacts["candidates"].head(3).assign(sphere_index=10**7)
    with pytest.raises(BadInputError, match="sphere_index"):
        candidate_lines(artefacts["classify"], stray, length=0.01)


def test_sphere_figure_shows_coloured_spheres_and_candidate_lines():
    artefacts = cylinder_chain()
    spheres, symmetry, candidates = artefacts["mat"], artefacts["classify"], artefacts["candidates"]
    before = candidates.copy()
    image = sphere_figure(spheres, symmetry, candidates, hand="armar3", title="cylinder", size=(900, 450))
    assert image.shape == (450, 900, 3) and image.dtype == np.uint8
    pd.testing.assert_frame_equal(candidates, before)  # input not modified
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50
    # the left plot (right of its colour bar): thin spheres at the cap edges red, the body's 5 cm spheres blue
    spheres_panel = image[:, 100:450]
    assert colour_mask(spheres_panel, (255, 0, 0), 60).sum() > 20
    assert colour_mask(spheres_panel, (0, 0, 255), 60).sum() > 200
    # the right plot: orange approach lines of the axis spheres, gone without candidates
    orange = np.round(np.array(CLASS_COLOURS["axis"]) * 255)
    assert colour_mask(image[:, 450:], orange, 30).sum() > 500
    bare = sphere_figure(spheres, symmetry, candidates.iloc[:0], size=(900, 450))
    assert colour_mask(bare[:, 450:], orange, 30).sum() == 0
    # deterministic: the same inputs give identical bytes
    again = sphere_figure(spheres, symmetry, candidates, hand="armar3", title="cylinder", size=(900, 450))
    assert image.tobytes() == again.tobytes()


# -- grasp pictures ----------------------------------------------------------------------------


def test_best_grasps_orders_by_epsilon_keeping_table_order_on_ties():
    _, trials = cylinder_trials()
    table = pd.concat([trials] * 3, ignore_index=True)
    table["epsilon"] = [0.1, 0.3, 0.3, 0.2, 0.5, 0.9]
    table.loc[4, "planner"] = "baseline"  # not a MAT trial
    table.loc[5, "outcome"] = "no_contact"  # not force closure
    assert best_grasps(table, count=3).index.tolist() == [1, 2, 3]
    assert best_grasps(table, count=10).index.tolist() == [1, 2, 3, 0]
    assert best_grasps(table, hand="armar3").empty


def test_grasp_images_show_the_closed_hand_on_the_object():
    surface, trials = cylinder_trials()
    images = grasp_images(surface, BARRETT, trials, count=3, size=(160, 120))
    assert len(images) == 2 and all(image.shape == (120, 160, 3) and image.dtype == np.uint8 for image in images)
    best = trials.loc[best_grasps(trials, count=1).index[0]]
    base = ((best.base_x, best.base_y, best.base_z), (best.base_qx, best.base_qy, best.base_qz, best.base_qw))
    for image in images:
        orange = (image[..., 0] > 150) & (image[..., 2] < 120)  # the object
        grey = (np.ptp(image.astype(int), axis=2) < 25) & (image.max(axis=2) < 230)  # the hand's links
        assert orange.mean() > 0.02 and grey.mean() > 0.05
    # the picture shows the trial's closed joints: with the open preshape the fingers move
    opened = render_hand(BARRETT, BARRETT.preshape(), base=base, surface=surface, size=(160, 120), frame="scene")
    assert np.abs(opened.astype(int) - images[0].astype(int)).sum(axis=2).astype(bool).mean() > 0.01
    assert len(grasp_images(surface, BARRETT, trials, count=1, size=(160, 120))) == 1
    again = grasp_images(surface, BARRETT, trials, count=3, size=(160, 120))
    assert [image.tobytes() for image in images] == [image.tobytes() for image in again]


def test_grasp_images_empty_without_force_closure_or_for_another_hand():
    surface, trials = cylinder_trials()
    assert grasp_images(surface, BARRETT, trials.assign(outcome="no_force_closure")) == []
    assert grasp_images(surface, HANDS["armar3"], trials) == []
    assert grasp_images(surface, BARRETT, trials.iloc[:0]) == []
    with pytest.raises(BadInputError, match="joints"):
        grasp_images(surface, BARRETT, trials.assign(joints=[[0.0, 0.1]] * len(trials)))


def test_render_hand_rejects_an_unknown_frame():
    with pytest.raises(ValueError, match="'object'"):
        render_hand(BARRETT, BARRETT.preshape(), frame="object")


# -- image grid --------------------------------------------------------------------------------


def test_image_grid_tiles_row_by_row_on_white():
    images = [np.full((10, 20, 3), value, np.uint8) for value in (10, 20, 30)]
    grid = image_grid(images, 2, pad=8)
    assert grid.shape == (8 + 2 * (10 + 8), 8 + 2 * (20 + 8), 3)
    assert (grid[8:18, 8:28] == 10).all() and (grid[8:18, 36:56] == 20).all() and (grid[26:36, 8:28] == 30).all()
    assert (grid[26:36, 36:56] == 255).all() and (grid[:8] == 255).all() and (grid[:, 28:36] == 255).all()
    assert image_grid(images, 5, pad=0).shape == (10, 60, 3)  # never more columns than images
    with pytest.raises(ValueError, match="empty"):
        image_grid([], 2)
    with pytest.raises(ValueError, match="columns"):
        image_grid(images, 0)

"""The cell grid of eq. 1 against brute force (property tests) and its stated invariants."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.geometry.cell_grid import CellGrid


def brute_force(points, queries, radius):
    distance = np.linalg.norm(points[None, :, :] - queries[:, None, :], axis=2)
    return [set(np.flatnonzero(row <= r)) for row, r in zip(distance, radius)], distance


clouds = st.tuples(
    st.integers(1, 400),  # points
    st.integers(1, 60),  # queries
    st.sampled_from(["cube", "flat", "line", "duplicates", "clustered"]),
    st.floats(0.0, 0.6),  # radius (bbox is ~1)
    st.floats(0.5, 8.0),  # cell density C
    st.integers(0, 2**32 - 1),  # seed
)


def make_cloud(count, layout, rng):
    points = rng.random((count, 3))
    if layout == "flat":
        points[:, 2] = 0.25
    elif layout == "line":
        points[:, 1:] = 0.5
    elif layout == "duplicates":
        points = points[rng.integers(0, max(count // 4, 1), count)]
    elif layout == "clustered":
        points = 0.5 + 0.01 * rng.standard_normal((count, 3))
        points[: count // 10] = rng.random((count // 10, 3))
    return points


@settings(max_examples=150, deadline=None)
@given(clouds)
def test_query_radius_equals_brute_force(case):
    count, n_queries, layout, radius, density, seed = case
    rng = np.random.default_rng(seed)
    points = make_cloud(count, layout, rng)
    queries = rng.random((n_queries, 3)) * 1.4 - 0.2  # some queries outside the bounding box
    radii = rng.random(n_queries) * radius
    grid = CellGrid.build(points, cell_density=density)
    indptr, indices, distances = grid.query_radius(queries, radii)
    expected, distance = brute_force(points, queries, radii)
    unsorted_indptr, unsorted, _ = grid.query_radius(queries, radii, sort=False)
    assert np.array_equal(unsorted_indptr, indptr)
    for row in range(n_queries):
        assert set(unsorted[indptr[row] : indptr[row + 1]]) == expected[row]
        hits = indices[indptr[row] : indptr[row + 1]]
        assert set(hits) == expected[row]
        assert len(hits) == len(expected[row])
        assert np.all(np.diff(distances[indptr[row] : indptr[row + 1]]) >= 0)
        np.testing.assert_allclose(distances[indptr[row] : indptr[row + 1]], distance[row, hits], rtol=1e-12)


@settings(max_examples=100, deadline=None)
@given(clouds)
def test_nearest_equals_brute_force(case):
    count, n_queries, layout, _, density, seed = case
    rng = np.random.default_rng(seed)
    points = make_cloud(count, layout, rng)
    queries = rng.random((n_queries, 3)) * 3.0 - 1.0
    distances, indices = CellGrid.build(points, cell_density=density).nearest(queries)
    _, distance = brute_force(points, queries, np.zeros(n_queries))
    np.testing.assert_allclose(distances, distance.min(axis=1), rtol=1e-12)
    np.testing.assert_allclose(distance[np.arange(n_queries), indices], distance.min(axis=1), rtol=1e-12)


def test_eq1_cubic_cells_about_n_over_c():
    # 10 x 2 x 1 box (k1 = 10): eq. 1 asks for cubic cells, about n / C of them
    rng = np.random.default_rng(0)
    points = rng.random((40000, 3)) * [10.0, 2.0, 1.0]
    grid = CellGrid.build(points, cell_density=4.0)
    assert np.isscalar(grid.cell_size) or np.ndim(grid.cell_size) == 0  # one edge: cubes
    cells = int(np.prod(grid.dims))
    assert 10000 <= cells <= 10000 * 1.5
    # cells are in proportion to the box edges: k1 (n/C)^(1/3) ... (n/C)^(1/3) / k1 for 10:2:1
    np.testing.assert_allclose(grid.dims / grid.dims[2], [10, 2, 1], rtol=0.2)
    assert np.all(np.diff(grid.cell_start) >= 0) and grid.cell_start[-1] == len(points)
    assert abs(np.mean(np.diff(grid.cell_start)) - 4.0) < 1.0


def test_build_does_not_modify_points_and_is_deterministic():
    points = np.random.default_rng(1).random((500, 3))
    before = points.copy()
    first, second = CellGrid.build(points), CellGrid.build(points)
    assert np.array_equal(points, before)
    assert np.array_equal(first.order, second.order) and np.array_equal(first.cell_start, second.cell_start)

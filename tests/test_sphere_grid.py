"""The grid of medial spheres: neighbourhood queries and the saved artefact."""

import numpy as np

from conftest import chain
from pipeline.artefacts import SphereGrid
from pipeline.geometry import sphere_grid


def test_neighbours_equal_brute_force_on_a_real_grid(tmp_path):
    grid = chain("torus", count=5000)["sphere_grid"]
    grid.save(tmp_path / "grid.npz")
    loaded = SphereGrid.load(tmp_path / "grid.npz")
    queries = loaded.centers[::7]
    indptr, indices, _ = sphere_grid.neighbours(loaded, queries, 0.01)
    distance = np.linalg.norm(loaded.centers[None] - queries[:, None], axis=2)
    for row in range(len(queries)):
        assert set(indices[indptr[row] : indptr[row + 1]]) == set(np.flatnonzero(distance[row] <= 0.01))


def test_sphere_grid_keeps_every_sphere():
    artefacts = chain("box", count=3000)
    grid = artefacts["sphere_grid"]
    assert len(grid) == len(artefacts["mat"])
    assert np.array_equal(np.sort(grid.order), np.arange(len(grid)))
    assert grid.cell_start[-1] == len(grid)

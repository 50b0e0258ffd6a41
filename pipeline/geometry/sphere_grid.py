"""The grid of medial spheres (stage ``sphere_grid``, paper II-B).

The medial spheres sorted by centre into the cubic cell grid of eq. 1, so the spheres in a
neighbourhood of radius ``r_search`` (paper III-B) are found by looking at nearby cells only.
"""

import numpy as np

from ..artefacts import SphereGrid, content_key
from .cell_grid import CellGrid


def build(spheres, *, cell_density=4.0):
    """The ``sphere_grid`` stage as a pure function.

    Parameters
    ----------
    spheres : MedialSpheres
    cell_density : float
        C of eq. 1, expected centres per cell.

    Returns
    -------
    SphereGrid
    """
    grid = CellGrid.build(spheres.centers, cell_density=cell_density)
    return SphereGrid(
        centers=spheres.centers,
        radii=spheres.radii,
        object_angle=spheres.object_angle,
        origin=grid.origin,
        dims=grid.dims,
        order=grid.order,
        cell_start=grid.cell_start,
        cell_size=grid.cell_size,
        key=content_key("sphere_grid", dict(cell_density=cell_density), spheres.key),
    )


def cell_grid(sphere_grid):
    """The :class:`CellGrid` stored in a SphereGrid artefact (no rebuild)."""
    return CellGrid(
        np.asarray(sphere_grid.centers),
        np.asarray(sphere_grid.origin),
        float(sphere_grid.cell_size),
        np.asarray(sphere_grid.dims),
        np.asarray(sphere_grid.order),
        np.asarray(sphere_grid.cell_start),
    )


def neighbours(sphere_grid, queries, radius):
    """Spheres whose centres lie within ``radius`` of each query point, nearest first.

    Parameters
    ----------
    sphere_grid : SphereGrid
    queries : (q, 3) float64, metres
    radius : float or (q,) float64, metres, inclusive

    Returns
    -------
    indptr : (q + 1,) int64
    indices : (hits,) int64, sphere ids
    distances : (hits,) float64
    """
    return cell_grid(sphere_grid).query_radius(queries, radius)

"""Symmetry analysis of the grid of medial spheres (stage ``classify``, paper III-A/B).

1. Selection: the reduced set is the spheres with object angle >= ``min_object_angle``,
   optionally within a diameter band (``min_diameter`` and ``max_diameter_ratio`` x the
   object's largest sphere diameter, the paper's d <= 0.3 d_max for object set 2).
2. For every selected sphere, its neighbourhood (the selected spheres whose centres lie
   within ``search_radius``) is analysed by PCA of the centres, all spheres at once. The
   selected centres are bucketed into cells of ``pca_cell_fraction`` x the search radius
   with their exact moments (count, centroid, scatter). Each cell's neighbourhood gathers
   the cells whose centroid lies within the radius of its centroid (a cell grid query), so
   its covariance is the exact covariance of those cells' spheres; one batched ``eigh``
   decomposes them all, and every sphere takes its cell's result. Neighbourhoods are thus
   resolved to a quarter of the search radius; ``pca_cell_fraction: 0`` makes every sphere
   its own cell (the paper's exact per-sphere analysis, slow on dense sphere sets).
3. Class by rho = l2 / l1 (paper eq. 2): ``axis`` (rho <= rho_axis), ``rim``
   (rho_axis < rho < rho_plane) or ``interior`` (rho >= rho_plane). Two cases the paper
   leaves open get classes of their own:

   - ``isolated``: the neighbourhood holds only the sphere itself, or its centres spread
     less than ``isolated_spread`` x the sphere's radius (sqrt(l1)): a perfectly spherical
     part, where PCA directions mean nothing. Candidates approach from fixed directions.
   - ``pair``: l2 = 0 (two spheres, or all centres on one line to 1e-12): e1 is the line
     through them and candidates are made as for an ``axis``.

The search radius is absolute (metres) or relative to the object: ``relative`` multiplies
the bounding-box diagonal of all sphere centres and radii, so the default 0.05 gives 1 cm
neighbourhoods on a 20 cm object (Simox's default 0.01 m), 1 mm on 2 cm and 10 cm on 2 m:
it scales linearly with the object.
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse

from ..arrays import group_rows
from ..artefacts import _Artefact, content_key
from ..errors import BadParamsError
from ..tol import tol

CLASSES = ("axis", "rim", "interior", "isolated", "pair")
AXIS, RIM, INTERIOR, ISOLATED, PAIR = range(len(CLASSES))


@dataclass(frozen=True)
class Symmetry(_Artefact):
    """Per selected sphere: class, PCA of its neighbourhood (``symmetry.npz``).

    sphere_index (s,) int64 into the sphere grid; class_id (s,) int64 into ``CLASSES``;
    rho (s,) float64 (nan where l1 = 0); eigenvalues (s, 3) float64, m^2, descending;
    axes (s, 9) float64, e1, e2, e3 as unit rows (reshape to (s, 3, 3)); cog (s, 3) float64,
    the neighbourhood's centre of gravity; neighbour_count (s,) int64, including the sphere;
    centers (s, 3) and radii (s,) of the selected spheres; search_radius, metres.
    """

    sphere_index: np.ndarray
    class_id: np.ndarray
    rho: np.ndarray
    eigenvalues: np.ndarray
    axes: np.ndarray
    cog: np.ndarray
    neighbour_count: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    search_radius: float
    key: str

    KIND = "symmetry"
    ARRAYS = {
        "sphere_index": (np.int64, None),
        "class_id": (np.int64, None),
        "rho": (np.float64, None),
        "eigenvalues": (np.float64, 3),
        "axes": (np.float64, 9),
        "cog": (np.float64, 3),
        "neighbour_count": (np.int64, None),
        "centers": (np.float64, 3),
        "radii": (np.float64, None),
    }

    def __len__(self):
        return len(self.sphere_index)

    def class_names(self):
        """(s,) array of class names."""
        return np.asarray(CLASSES)[self.class_id]


def select(sphere_grid, *, min_object_angle, min_diameter=0.0, max_diameter_ratio=1.0):
    """Indices of the reduced sphere set (paper III-A).

    Parameters
    ----------
    sphere_grid : SphereGrid
    min_object_angle : float, radians
    min_diameter : float, metres
    max_diameter_ratio : float
        Keep d <= ratio x (largest diameter of the object); 1 keeps all.

    Returns
    -------
    (s,) int64
    """
    diameter = 2.0 * np.asarray(sphere_grid.radii)
    keep = (np.asarray(sphere_grid.object_angle) >= min_object_angle) & (diameter >= min_diameter)
    keep &= diameter <= max_diameter_ratio * diameter.max()
    return np.flatnonzero(keep)


def cell_moments(centers, cell_size):
    """Bucket points into cubic cells and return each cell's exact first and second moments.

    Parameters
    ----------
    centers : (n, 3) float64
    cell_size : float; 0 makes every distinct point its own cell

    Returns
    -------
    centroid : (c, 3) float64
    count : (c,) int64
    scatter : (c, 3, 3) float64, sum of outer products about the centroid
    cell : (n,) int64, the cell of every point
    """
    if cell_size > 0:
        cells = np.floor(centers / cell_size).astype(np.int64)
    else:
        cells = np.ascontiguousarray(centers).view(np.int64)  # bit patterns: one cell per distinct point
    _, inverse = group_rows(cells)
    count = np.bincount(inverse)
    centroid = np.stack([np.bincount(inverse, centers[:, axis]) for axis in range(3)], axis=1) / count[:, None]
    offset = centers - centroid[inverse]
    outer = (offset[:, :, None] * offset[:, None, :]).reshape(-1, 9)
    scatter = np.stack([np.bincount(inverse, outer[:, k], len(count)) for k in range(9)], axis=1)
    return centroid, count, scatter.reshape(-1, 3, 3), inverse


def neighbourhood_pca(queries, radius, centroid, count, scatter):
    """Batched PCA of the centres within ``radius`` of each query, from cell moments.

    A cell belongs to a neighbourhood when its centroid is within ``radius``; its members'
    contribution is then exact (count, centroid and scatter), so with one point per cell
    this is the exact PCA of every neighbourhood.

    Parameters
    ----------
    queries : (s, 3) float64
    radius : float
    centroid, count, scatter : from :func:`cell_moments`

    Returns
    -------
    eigenvalues : (s, 3) float64, descending (population covariance, m^2)
    axes : (s, 3, 3) float64, rows e1, e2, e3
    cog : (s, 3) float64, the neighbourhood's centre of gravity
    members : (s,) int64, number of centres in the neighbourhood
    """
    from .cell_grid import CellGrid

    indptr, cell, _ = CellGrid.build(centroid).query_radius(queries, radius, sort=False)
    # moments about a common origin near the data (for conditioning), summed per
    # neighbourhood by one sparse product: rows = queries, columns = cells
    origin = centroid.mean(axis=0)
    local = centroid - origin
    weight = count.astype(np.float64)
    second = scatter + weight[:, None, None] * local[:, :, None] * local[:, None, :]
    features = np.column_stack([weight, weight[:, None] * local, second.reshape(-1, 9)])
    membership = scipy.sparse.csr_matrix((np.ones(len(cell)), cell, indptr), shape=(len(queries), len(centroid)))
    summed = membership @ features
    members = summed[:, 0]
    safe = np.maximum(members, 1.0)
    mean = summed[:, 1:4] / safe[:, None]
    covariance = summed[:, 4:].reshape(-1, 3, 3) / safe[:, None, None] - mean[:, :, None] * mean[:, None, :]
    values, vectors = np.linalg.eigh(covariance)
    values = np.clip(values[:, ::-1], 0.0, None)
    axes = vectors[:, :, ::-1].transpose(0, 2, 1)
    # fix each eigenvector's sign so results do not depend on LAPACK: largest component positive
    flip = np.take_along_axis(axes, np.abs(axes).argmax(axis=2)[:, :, None], axis=2) < 0
    axes = np.where(flip, -axes, axes)
    return values, axes, origin + mean, np.rint(members).astype(np.int64)


def classify(
    sphere_grid,
    *,
    min_object_angle_deg=120.0,
    min_diameter_m=0.0,
    max_diameter_ratio=1.0,
    search_radius=0.05,
    search_radius_unit="relative",
    rho_axis=0.01,
    rho_plane=0.4,
    isolated_spread=0.05,
    pca_cell_fraction=0.25,
):
    """The ``classify`` stage as a pure function.

    Parameters
    ----------
    sphere_grid : SphereGrid
    min_object_angle_deg : float, degrees
    min_diameter_m : float, metres
    max_diameter_ratio : float
    search_radius : float
        Metres, or a fraction of the object's bounding-box diagonal (see module docstring).
    search_radius_unit : {'relative', 'metres'}
    rho_axis, rho_plane : float
        Paper III-B thresholds on rho = l2 / l1.
    isolated_spread : float
        A neighbourhood whose centres spread less than this x the sphere radius is ``isolated``.
    pca_cell_fraction : float
        Neighbourhoods are gathered from cells of this x the search radius, with exact
        per-cell moments (see :func:`neighbourhood_pca`); 0 = sphere by sphere, exact.

    Returns
    -------
    Symmetry
    """
    params = dict(
        min_object_angle_deg=min_object_angle_deg,
        min_diameter_m=min_diameter_m,
        max_diameter_ratio=max_diameter_ratio,
        search_radius=search_radius,
        search_radius_unit=search_radius_unit,
        rho_axis=rho_axis,
        rho_plane=rho_plane,
        isolated_spread=isolated_spread,
        pca_cell_fraction=pca_cell_fraction,
    )
    if search_radius_unit not in ("relative", "metres"):
        raise BadParamsError(
            f"params: classify.search_radius_unit must be 'relative' or 'metres', got {search_radius_unit!r}"
        )
    centers, radii = np.asarray(sphere_grid.centers), np.asarray(sphere_grid.radii)
    if search_radius_unit == "relative":
        extent = np.ptp(np.concatenate([centers - radii[:, None], centers + radii[:, None]]), axis=0)
        radius = search_radius * float(np.linalg.norm(extent))
    else:
        radius = float(search_radius)
    selected = select(
        sphere_grid,
        min_object_angle=np.radians(min_object_angle_deg),
        min_diameter=min_diameter_m,
        max_diameter_ratio=max_diameter_ratio,
    )
    if not len(selected):  # nothing passes the object-angle filter: no symmetry to find, no candidates
        eigenvalues, axes, cog, counts = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0, int)
    else:  # only the reduced set takes part in the analysis (paper III-B)
        centroid, count, scatter, cell = cell_moments(centers[selected], pca_cell_fraction * radius)
        # one neighbourhood per cell, centred on the cell's centroid: the spheres of a cell share it
        eigenvalues, axes, cog, counts = (
            value[cell] for value in neighbourhood_pca(centroid, radius, centroid, count, scatter)
        )
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = np.where(eigenvalues[:, 0] > 0, eigenvalues[:, 1] / eigenvalues[:, 0], np.nan)
    class_id = np.full(len(selected), INTERIOR)
    class_id[rho < rho_plane] = RIM
    class_id[rho <= rho_axis] = AXIS
    class_id[(counts == 2) | (eigenvalues[:, 1] <= tol.pair_spread * eigenvalues[:, 0])] = PAIR
    spread = np.sqrt(eigenvalues[:, 0])
    class_id[(counts == 1) | (spread < isolated_spread * radii[selected])] = ISOLATED
    return Symmetry(
        sphere_index=selected,
        class_id=class_id,
        rho=rho,
        eigenvalues=eigenvalues,
        axes=axes.reshape(-1, 9),
        cog=cog,
        neighbour_count=counts,
        centers=centers[selected],
        radii=radii[selected],
        search_radius=radius,
        key=content_key("classify", params, sphere_grid.key),
    )

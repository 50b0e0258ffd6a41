"""The cubic cell grid of the paper's eq. 1, for nearest-point and radius searches.

Points are bucketed into cubic cells of edge ``cell_size`` spanning their bounding box,
about ``n / C`` cells in all (C, the cell density, is the expected number of points per
cell: 4 in general, 2 for thin objects). The paper writes the grid as
``k1 (n/C)^(1/3) x (n/C)^(1/3) x (n/C)^(1/3) / k1`` cells; we keep its two invariants,
cubic cells and ``n / C`` cells, for any box proportions by choosing
``cell_size = (box volume / (n / C))^(1/3)``. Points are stored sorted by cell (a
counting sort, linear time), so a cell's points are one contiguous slice.

Queries are vectorised over all query points: each query's block of cells is enumerated,
the cells' point slices flattened, and distances filtered, with no per-query Python loop.

References
----------
Bentley, Weide, Yao, "Optimal expected-time algorithms for closest point problems",
ACM TOMS 6(4), 1980. Przybylski et al., IROS 2011, section II-A.
"""

from dataclasses import dataclass

import numpy as np

from ..arrays import expand_ranges
from ..errors import BadInputError
from ..validate import as_points

_CHUNK_CELLS = 1 << 21  # cell visits per vectorised batch: bounds temporary memory


@dataclass(frozen=True)
class CellGrid:
    """Points bucketed into cubic cells.

    Attributes
    ----------
    points : (n, 3) float64
    origin : (3,) float64, the bounding box's minimum corner
    cell_size : float, edge of a cubic cell, same unit as points
    dims : (3,) int64, cells along x, y, z
    order : (n,) int64, point indices sorted by cell id
    cell_start : (cells + 1,) int64, cell ``c`` holds ``order[cell_start[c]:cell_start[c + 1]]``
    """

    points: np.ndarray
    origin: np.ndarray
    cell_size: float
    dims: np.ndarray
    order: np.ndarray
    cell_start: np.ndarray

    @classmethod
    def build(cls, points, *, cell_density=4.0):
        """Bucket ``points`` ((n, 3) float64) into about ``n / cell_density`` cubic cells."""
        points = as_points("points", points)
        if not cell_density > 0:
            raise BadInputError(f"cell_density: must be > 0, got {cell_density!r}")
        origin = points.min(axis=0)
        extent = points.max(axis=0) - origin
        longest = float(extent.max())
        if longest == 0:
            cell_size = 1.0
        else:
            # a flat or linear point set still gets a finite cell: thin axes count as 1e-3 of the longest
            span = np.maximum(extent, 1e-3 * longest)
            cell_size = float(np.cbrt(np.prod(span) / max(len(points) / cell_density, 1.0)))
        dims = np.maximum(np.ceil(extent / cell_size).astype(np.int64), 1)
        cell_ids = cls._flat_id(cls._clipped_cell(points, origin, cell_size, dims), dims)
        order = np.argsort(cell_ids, kind="stable")
        cell_start = np.concatenate([[0], np.cumsum(np.bincount(cell_ids, minlength=int(np.prod(dims))))])
        return cls(points, origin, cell_size, dims, order, cell_start)

    @staticmethod
    def _clipped_cell(xyz, origin, cell_size, dims):
        return np.clip(np.floor((xyz - origin) / cell_size).astype(np.int64), 0, dims - 1)

    @staticmethod
    def _flat_id(cell, dims):
        return (cell[..., 0] * dims[1] + cell[..., 1]) * dims[2] + cell[..., 2]

    def __len__(self):
        return len(self.points)

    def query_radius(self, queries, radius, *, sort=True):
        """All points within ``radius`` of each query, nearest first.

        Parameters
        ----------
        queries : (q, 3) float64
        radius : float or (q,) float64
            Inclusive search radius per query.
        sort : bool
            Order each query's hits by distance (ties by index); otherwise in cell order.

        Returns
        -------
        indptr : (q + 1,) int64
            Query ``i``'s hits are ``indices[indptr[i]:indptr[i + 1]]``.
        indices : (hits,) int64, point indices sorted by distance (ties by index)
        distances : (hits,) float64
        """
        queries = as_points("queries", queries, allow_empty=True)
        radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (len(queries),))
        if not (np.isfinite(radius).all() and (radius >= 0).all()):
            raise BadInputError("radius: must be finite and >= 0")
        low = self._clipped_cell(queries - radius[:, None], self.origin, self.cell_size, self.dims)
        high = self._clipped_cell(queries + radius[:, None], self.origin, self.cell_size, self.dims)
        sizes = high - low + 1
        cells_per_query = np.prod(sizes, axis=1)
        owners, indices, distances = [], [], []
        bounds = np.searchsorted(
            np.cumsum(cells_per_query), np.arange(_CHUNK_CELLS, cells_per_query.sum(), _CHUNK_CELLS), side="right"
        )
        for first, last in zip(np.r_[0, bounds], np.r_[bounds, len(queries)]):
            chunk = slice(first, last)
            query_of_cell, local = expand_ranges(np.zeros(last - first), cells_per_query[chunk])
            size = sizes[chunk][query_of_cell]
            offset = np.stack(
                [local // (size[:, 1] * size[:, 2]), (local // size[:, 2]) % size[:, 1], local % size[:, 2]], axis=1
            )
            cell = self._flat_id(low[chunk][query_of_cell] + offset, self.dims)
            start = self.cell_start[cell]
            cell_of_hit, position = expand_ranges(start, self.cell_start[cell + 1] - start)
            query = query_of_cell[cell_of_hit] + first
            point = self.order[position]
            distance = np.linalg.norm(self.points[point] - queries[query], axis=1)
            inside = distance <= radius[query]
            owners.append(query[inside])
            indices.append(point[inside])
            distances.append(distance[inside])
        owner = np.concatenate(owners) if owners else np.zeros(0, np.int64)
        index = np.concatenate(indices) if indices else np.zeros(0, np.int64)
        distance = np.concatenate(distances) if distances else np.zeros(0)
        indptr = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=len(queries)))])
        if not sort:  # hits are generated query by query, so already grouped
            return indptr, index, distance
        order = np.lexsort((index, distance, owner))
        return indptr, index[order], distance[order]

    def nearest(self, queries):
        """Exact nearest point of each query (Bentley's expanding search).

        The search radius starts at one cell and doubles for the queries that found
        nothing yet, so cells are examined from the query's own cell outward; once a
        point is found, every cell that could hold a closer one has been examined.

        Parameters
        ----------
        queries : (q, 3) float64

        Returns
        -------
        distances : (q,) float64
        indices : (q,) int64
        """
        queries = as_points("queries", queries, allow_empty=True)
        distances = np.full(len(queries), np.inf)
        indices = np.full(len(queries), -1, dtype=np.int64)
        active = np.arange(len(queries))
        radius = np.full(len(queries), self.cell_size)
        while active.size:
            indptr, hits, hit_distance = self.query_radius(queries[active], radius[active])
            found = np.diff(indptr) > 0
            first = indptr[:-1][found]
            distances[active[found]] = hit_distance[first]
            indices[active[found]] = hits[first]
            active = active[~found]
            radius[active] *= 2.0
        return distances, indices

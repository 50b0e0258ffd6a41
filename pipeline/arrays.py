"""Small vectorised array helpers shared by the geometry modules."""

import numpy as np


def unit_rows(vectors):
    """Rows of ``vectors`` scaled to unit length; zero rows stay zero.

    Parameters
    ----------
    vectors : (n, d) float64

    Returns
    -------
    (n, d) float64
    """
    norms = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.divide(vectors, norms, out=np.zeros_like(vectors), where=norms > 0)


def expand_ranges(starts, counts):
    """Flatten the integer ranges ``[starts[i], starts[i] + counts[i])`` without a Python loop.

    Returns
    -------
    owner : (counts.sum(),) int64
        Index ``i`` of the range each value came from.
    values : (counts.sum(),) int64
    """
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(len(counts)), counts)
    first = np.cumsum(counts) - counts
    values = np.repeat(np.asarray(starts, dtype=np.int64) - first, counts) + np.arange(counts.sum())
    return owner, values


def padded_rows(indptr, values, width, *, fill=-1):
    """The first ``width`` values of each CSR row as a dense ``(rows, width)`` array padded with ``fill``."""
    rows = len(indptr) - 1
    counts = np.diff(indptr)
    owner, position = expand_ranges(indptr[:-1], np.minimum(counts, width))
    out = np.full((rows, width), fill, dtype=np.asarray(values).dtype)
    out[owner, position - indptr[:-1][owner]] = values[position]
    return out


def group_rows(rows):
    """Group identical rows of an integer array (e.g. cell indices) without a Python loop.

    Parameters
    ----------
    rows : (n, d) int64

    Returns
    -------
    first : (g,) int64, index of each group's first row, groups in sorted-key order
    inverse : (n,) int64, the group of every row
    """
    rows = np.ascontiguousarray(rows, dtype=np.int64)
    keys = rows.view(np.dtype((np.void, rows.itemsize * rows.shape[1]))).ravel()
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    return first, inverse.ravel()


def vectors(table, prefix):
    """The ``(n, 3)`` array of a table's columns ``{prefix}_x, _y, _z`` (prefix grasp, approach or orient)."""
    return table[[f"{prefix}_x", f"{prefix}_y", f"{prefix}_z"]].to_numpy()

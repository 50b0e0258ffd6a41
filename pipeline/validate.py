"""The one shared input checker for array arguments."""

import numpy as np

from .errors import BadInputError


def as_points(name, array, *, columns=3, allow_empty=False):
    """Return ``array`` as a C-contiguous ``(n, columns)`` float64 array, or raise.

    Parameters
    ----------
    name : str
        Argument name, used in the error message.
    array : array_like
        The values to check; never modified.
    columns : int
        Required number of columns.
    allow_empty : bool
        Whether ``n == 0`` is acceptable.

    Raises
    ------
    BadInputError
        If the shape is wrong, the array is empty (unless allowed) or holds NaN/inf.
    """
    values = np.ascontiguousarray(array, dtype=np.float64)
    if values.ndim != 2 or values.shape[1] != columns:
        raise BadInputError(f"{name}: expected shape (n, {columns}), got {values.shape}")
    if values.shape[0] == 0 and not allow_empty:
        raise BadInputError(f"{name}: is empty")
    if not np.isfinite(values).all():
        raise BadInputError(f"{name}: holds NaN or infinite values")
    return values

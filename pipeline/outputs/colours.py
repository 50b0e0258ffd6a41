"""Colours shared by the report's figures (:mod:`pipeline.outputs.figures`) and the rerun recordings
(:mod:`pipeline.outputs.recording`): RGB floats in [0, 1], after the paper's Fig. 5."""

import numpy as np

from ..errors import BadInputError

#: approach-line colour of each sphere class (paper Fig. 5: orange axis, green plane)
CLASS_COLOURS = {
    "axis": (1.0, 0.55, 0.0),
    "rim": (0.1, 0.65, 0.1),
    "pair": (0.6, 0.3, 0.75),
    "isolated": (0.0, 0.6, 0.85),
    "encompassing": (0.85, 0.0, 0.35),
}
CLASS_LABELS = {
    "axis": "P_d, symmetry axis",
    "rim": "P_d, symmetry plane (rim)",
    "pair": "P_d, pair",
    "isolated": "P_d, isolated sphere",
    "encompassing": "P_d, encompassing a concavity",
}
E1_COLOUR, E2_COLOUR, ORIENT_COLOUR, REDUCED_COLOUR = (0.75, 0.0, 0.0), (0.1, 0.25, 0.8), (1.0, 0.0, 1.0), (0.6,) * 3


def diameter_colours(diameters):
    """RGB colours from red (smallest diameter) over green (mid-range) to blue (largest).

    Parameters
    ----------
    diameters : (n,) float, metres

    Returns
    -------
    (n, 3) float64 in [0, 1]; linear in the diameter, piecewise between red, green and blue.
    All green when every diameter is the same.
    """
    values = np.asarray(diameters, dtype=np.float64)
    if values.ndim != 1:
        raise BadInputError(f"diameters: expected shape (n,), got {values.shape}")
    if not np.isfinite(values).all():
        raise BadInputError("diameters: holds NaN or infinite values")
    span = np.ptp(values) if len(values) else 0.0
    t = (values - values.min()) / span if span > 0 else np.full(len(values), 0.5)
    return np.column_stack(
        [np.clip(1.0 - 2.0 * t, 0.0, 1.0), 1.0 - np.abs(2.0 * t - 1.0), np.clip(2.0 * t - 1.0, 0.0, 1.0)]
    )

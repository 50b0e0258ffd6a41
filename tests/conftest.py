"""Shared fixtures: analytic shapes run through the geometry chain once per session."""

import functools

import numpy as np
import pytest

from pipeline.params import Params, SampleParams, defaults
from pipeline.plan import run_chain

SHAPES = {
    # name: (source, shape keywords); sizes in metres
    "box": ("primitive:box", dict(extents=[0.10, 0.06, 0.02])),
    "capsule": ("primitive:capsule", dict(radius=0.02, height=0.10)),
    "cylinder": ("primitive:cylinder", dict(radius=0.025, height=0.12)),
    "sphere": ("primitive:sphere", dict(radius=0.04)),
    "plate": ("primitive:plate", dict(extents=[0.10, 0.10, 0.006])),
    "torus": ("primitive:torus", dict(major_radius=0.05, minor_radius=0.012)),
}


@functools.lru_cache(maxsize=None)
def chain(name, count=20000, method="shrinking_ball"):
    """Artefacts of sample -> medial_axis -> mat -> sphere_grid for a named analytic shape."""
    from pipeline.params import MedialAxisParams

    source, shape = SHAPES[name]
    params = Params(sample=SampleParams(count=count), medial_axis=MedialAxisParams(method=method))
    artefacts, _ = run_chain(source, params, shape=shape, seed=7)
    return artefacts


def complete_params(overrides=None):
    """A complete params dict (every key is required): the defaults with ``overrides`` merged into
    their sections; figures only of objects that ``overrides`` names."""
    params = defaults()
    for key, value in (overrides or {}).items():
        merge = isinstance(value, dict) and isinstance(params.get(key), dict) and key != "objects"
        params[key] = {**params[key], **value} if merge else value
    if "figure_objects" not in (overrides or {}).get("report", {}):
        params["report"]["figure_objects"] = [
            name for name in params["report"]["figure_objects"] if name in params["objects"]
        ]
    return params


@pytest.fixture
def rng():
    return np.random.default_rng(12345)

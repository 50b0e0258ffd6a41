"""The paper's statements on its figures, checked on the procedural analogues of its objects.

Candidates only (no simulation), default params, seed 0, both hands. Every region below is
written from the dimensions in the builder (pipeline/geometry/procedural.py), in the object frame at
scale 1; a candidate is where its sphere's centre is (the paper's P_g; a rim candidate's P_g
moves across a thin wall's rim to centre the hand on the material between its fingers, which
does not change the part it grasps).
"""

import functools

import numpy as np
import pytest

from pipeline.hands.spec import get_hand
from pipeline.params import Params
from pipeline.plan import run_chain

HANDS = ("armar3", "barrett")


@functools.lru_cache(maxsize=None)
def planned(name, scale=1.0):
    """(candidates, symmetry) of ``primitive:NAME`` at ``scale``, both hands, seed 0."""
    artefacts, _ = run_chain(f"primitive:{name}", Params(), scale=scale, seed=0, hands=list(HANDS))
    return artefacts["candidates"], artefacts["classify"]


def grasp_points(name, hand, scale=1.0):
    """(n, 3) sphere centres of ``hand``'s candidates from the paper's planner (not those that
    encompass a concavity, its future work), divided by ``scale`` (builder frame)."""
    candidates, symmetry = planned(name, scale)
    rows = (candidates.hand == hand) & (candidates.sphere_class != "encompassing")
    spheres = np.searchsorted(symmetry.sphere_index, candidates.sphere_index[rows])
    return np.asarray(symmetry.centers)[spheres] / scale


def near_segment(points, start, end, radius):
    """(n,) bool: within ``radius`` of the segment ``start``-``end``."""
    start, end = np.asarray(start, float), np.asarray(end, float)
    t = np.clip((points - start) @ (end - start) / ((end - start) @ (end - start)), 0, 1)
    return np.linalg.norm(points - (start + t[:, None] * (end - start)), axis=1) <= radius


def near_circle(points, centre, radius, tube):
    """(n,) bool: within ``tube`` of the circle of ``radius`` about ``centre`` in the xz plane."""
    offset = points - np.asarray(centre, float)
    return np.hypot(np.hypot(offset[:, 0], offset[:, 2]) - radius, offset[:, 1]) <= tube


def in_ellipsoid(points, centre, semi_axes):
    return (((points - np.asarray(centre)) / np.asarray(semi_axes)) ** 2).sum(axis=1) <= 1.0


# --- Fig. 8: the giraffe's torso is too thick at full scale, graspable at 25 % -------------------

TORSO_CENTRE, TORSO_SEMI_AXES = (0.0, 0.0, 0.75), (0.30, 0.13, 0.13)  # quadruped(): 0.60 x 0.26 x 0.26 m


def giraffe_regions(points):
    """Torso (its ellipsoid shrunk to 85 %: the legs, neck and tail join it at its surface),
    legs (below the torso's underside at z 0.62), neck and head (from quadruped())."""
    return {
        "torso": in_ellipsoid(points, TORSO_CENTRE, 0.85 * np.asarray(TORSO_SEMI_AXES)),
        "legs": points[:, 2] < 0.6,
        "neck": near_segment(points, [0.22, 0, 0.8], [0.45, 0, 1.25], 0.035),
        "head": in_ellipsoid(points, (0.5, 0, 1.28), (0.09, 0.045, 0.045)),
    }


@pytest.mark.parametrize("hand", HANDS)
def test_fig8_full_scale_giraffe_is_grasped_only_at_its_extremities(hand):
    regions = giraffe_regions(grasp_points("quadruped", hand))
    assert regions["torso"].sum() == 0
    assert regions["legs"].sum() > 0 and regions["neck"].sum() > 0 and regions["head"].sum() > 0
    # the reason: the torso does hold spheres of the reduced set, all thicker than the hand's limit
    _, symmetry = planned("quadruped")
    torso = giraffe_regions(symmetry.centers)["torso"]
    assert torso.sum() > 0
    assert (2 * symmetry.radii[torso]).min() > get_hand(hand).max_graspable_diameter


@pytest.mark.parametrize("hand", HANDS)
def test_fig8_quarter_scale_giraffe_torso_is_graspable(hand):
    regions = giraffe_regions(grasp_points("quadruped", hand, scale=0.25))
    assert regions["torso"].sum() > 0
    assert regions["legs"].sum() > 0 and regions["neck"].sum() > 0


# --- Fig. 10: handles (and rims) are grasped, the hollow or thick body is not --------------------


def mug_regions(points):
    """mug(): body radius 5 cm, 12 cm tall; handle ring of radius 3.5 cm about (0.05, 0, 0.06),
    tube 8 mm, outside the body; rim: the top centimetre of the wall."""
    rim = points[:, 2] > 0.11
    handle = near_circle(points, (0.05, 0, 0.06), 0.035, 0.008) & (points[:, 0] > 0.05)
    return {"handle": handle, "rim": rim, "body": ~(handle | rim)}


def kettle_regions(points):
    """kettle(): handle arc of radius 7 cm above z 0.13, tube 8 mm; spout from (-0.06, 0, 0.05),
    0.11 m long at 45 deg, radius up to 1.8 cm; lid knob of radius 1.2 cm at z 0.165."""
    handle = near_circle(points, (0, 0, 0.13), 0.07, 0.008) & (points[:, 2] > 0.125)
    spout = near_segment(points, [-0.06, 0, 0.05], [-0.06 - 0.11 / np.sqrt(2), 0, 0.05 + 0.11 / np.sqrt(2)], 0.018)
    knob = np.linalg.norm(points - [0, 0, 0.165], axis=1) <= 0.012
    return {"handle": handle, "spout": spout, "knob": knob, "body": ~(handle | spout | knob)}


def vase_regions(points):
    """vase(): each handle is three limbs of 8 mm radius through (+-0.028, 0, 0.21),
    (+-0.10, 0, 0.21), (+-0.10, 0, 0.14), (+-0.065, 0, 0.14); lip: above z 0.235."""
    handle = np.zeros(len(points), bool)
    for side in (-1, 1):
        corners = np.array([[0.028, 0, 0.21], [0.10, 0, 0.21], [0.10, 0, 0.14], [0.065, 0, 0.14]]) * [side, 1, 1]
        for start, end in zip(corners, corners[1:]):
            handle |= near_segment(points, start, end, 0.008)
    lip = points[:, 2] > 0.235
    return {"handle": handle, "lip": lip, "body": ~(handle | lip)}


REGIONS = {"mug": mug_regions, "kettle": kettle_regions, "vase": vase_regions}
# Paper, Sec. IV: "mainly grasps at the handles ... as in both cases the hollow body is too thick to
# grasp" (tea pot, vase); Sec. V: a cup is grasped "at the handle and at the rim of the concavity".
MAINLY = {"mug": 0.99, "kettle": 0.99, "vase": 0.8}


@pytest.mark.parametrize("hand", HANDS)
@pytest.mark.parametrize("name", sorted(REGIONS))
def test_fig10_handles_are_grasped_and_the_body_hardly_ever(name, hand):
    regions = REGIONS[name](grasp_points(name, hand))
    count = len(regions["body"])
    assert regions["handle"].sum() > 0
    assert regions["handle"].sum() / count >= 0.5
    assert 1.0 - regions["body"].sum() / count >= MAINLY[name]

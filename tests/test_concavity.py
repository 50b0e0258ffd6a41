"""Concavities and the grasps that encompass them (stage ``concavity``; the paper's section V).

Known answers: the procedural mug of radius 4 cm (8 cm body, inside the ARMAR-III limit of
9.4 cm) has a cylindrical hollow of radius 3.4 cm and depth 11.2 cm opening through its flat
top; the space in its handle's loop opens all around the handle, not through one flat mouth; the vase's hollow is 16-17 cm wide, beyond both
hands; a box, a capsule and a torus (whose hole opens on two sides) have no container.
"""

import functools

import numpy as np
import pytest

from pipeline.artefacts import SurfaceSamples
from pipeline.errors import BadParamsError
from pipeline.geometry.candidates import generate_for_hands
from pipeline.geometry.concavity import Concavities, encompass
from pipeline.geometry.sampling import sample_object
from pipeline.geometry.symmetry import classify
from pipeline.hands.spec import get_hand
from pipeline.params import ConcavityParams, SampleParams
from pipeline.trial.protocol import simulate

ARMAR3, BARRETT = get_hand("armar3"), get_hand("barrett")
BODY, WALL, HEIGHT, BASE = 0.04, 0.006, 0.12, 0.008


@functools.cache
def planned(source, scale=1.0, radius=None):
    """(surface, concavities) of a source at the default params, seed 0."""
    import dataclasses

    surface = sample_object(
        source,
        rng=np.random.default_rng(0),
        scale=scale,
        shape=None if radius is None else {"radius": radius},
        **dataclasses.asdict(SampleParams()),
    )
    return surface, encompass(surface)


def test_mug_hollow_is_the_one_counted_concavity_with_its_analytic_size():
    _, found = planned("primitive:mug", radius=BODY)
    hollow = BODY - WALL
    assert found.counted.sum() == 1
    cup = int(np.flatnonzero(found.counted)[0])
    assert found.volume[cup] == pytest.approx(np.pi * hollow**2 * (HEIGHT - BASE), rel=0.01)  # a 96-gon
    assert found.width[cup] == pytest.approx(2 * hollow, abs=0.002)
    assert found.mouth_width[cup] == pytest.approx(2 * hollow, abs=0.001) and found.mouths[cup] == 1
    # the handle's loop is a concavity too, but its opening wraps around the handle: not a container
    assert len(found.volume) >= 2 and not found.flat[found.volume < found.volume[cup]].any()
    # every encompassing sphere lies in the hollow, on the body's axis, as wide as the body
    assert len(found) > 0 and (found.part == cup).all()
    assert np.abs(found.centers[:, :2]).max() < 0.002
    assert ((found.centers[:, 2] > BASE) & (found.centers[:, 2] < HEIGHT)).all()
    assert np.allclose(2 * found.radii, 2 * BODY, atol=0.002)


def test_mug_encompassing_candidates_surround_the_body_and_mostly_close():
    surface, found = planned("primitive:mug", radius=BODY)
    symmetry = classify_plain(surface)
    table = generate_for_hands(symmetry, found, [ARMAR3])
    around = table[table.sphere_class == "encompassing"]
    assert len(around) > 0 and len(table) > len(around)  # the handle and rim candidates stay
    grasp = around[["grasp_x", "grasp_y", "grasp_z"]].to_numpy()
    # around the body's axis, none on the handle (x beyond the body) nor inside its loop
    assert np.abs(grasp[:, :2]).max() < 0.002 and (grasp[:, 0] < BODY).all()
    # each approach is across the axis (P_d horizontal), wrapping around it (P_o vertical)
    assert np.abs(around.approach_z).max() < 0.05 and (np.abs(around.orient_z) > 0.99).all()
    trials, contacts = simulate(surface, table, [ARMAR3], spheres_per_object=5, baseline_trials=0, seed=0, workers=1)
    mine = trials[trials.planner == "encompassing"]
    assert len(mine) == 5 * 8 and (trials.planner == "mat").sum() > 0
    assert (mine.outcome == "force_closure").mean() >= 0.5
    # tried against the real mug: the fingers close on the body's outside wall
    touching = contacts[contacts.trial.isin(np.flatnonzero((trials.planner == "encompassing").to_numpy()))]
    radius = np.hypot(touching.x, touching.y)
    body = touching.z.between(0.0, HEIGHT) & (touching.x < BODY + 0.002)
    assert np.allclose(radius[body & (touching.link > 0)], BODY, atol=0.003)
    # and push along the body's own normal: the 96-gon's facets are within 1.875 deg of radial,
    # and an edge's contact normal stays in its cone (not a fingertip's tilt: a fabricated pinch);
    # away from the handle's roots (8 mm tube, +x), where the wall meets it at a sharp crease
    wall = body & (touching.link > 0) & np.isclose(radius, BODY, atol=0.0005) & touching.z.between(0.01, HEIGHT - 0.01)
    wall &= (touching.x < 0) | (np.abs(touching.y) > 0.02)
    outward = np.c_[touching.x, touching.y][wall] / radius[wall].to_numpy()[:, None]
    across = np.c_[touching.nx, touching.ny][wall]
    cosine = (outward * across).sum(axis=1) / np.linalg.norm(across, axis=1)
    assert wall.sum() > 10 and np.degrees(np.arccos(np.clip(cosine, -1, 1))).max() < 2.0


def classify_plain(surface):
    from pipeline.geometry.mat import reconstruct
    from pipeline.geometry.medial_axis import medial_axis
    from pipeline.geometry.sphere_grid import build

    return classify(build(reconstruct(surface, medial_axis(surface))))


def test_vase_hollow_is_too_wide_for_both_hands():
    _, found = planned("primitive:vase")
    assert found.counted.sum() == 1 and found.width[found.counted][0] > BARRETT.max_graspable_diameter
    for hand in (ARMAR3, BARRETT):
        assert len(found.spheres_for(hand.max_graspable_diameter)) == 0
    symmetry = classify_plain(planned("primitive:vase")[0])
    table = generate_for_hands(symmetry, found, [ARMAR3, BARRETT])
    assert len(table) > 0 and not (table.sphere_class == "encompassing").any()
    # a hand allowed twice its limit would reach around it (the param decides)
    assert len(found.spheres_for(BARRETT.max_graspable_diameter, 2.0)) > 0


@pytest.mark.parametrize("source", ["primitive:box", "primitive:capsule", "primitive:torus"])
def test_objects_without_a_container_get_no_encompassing_sphere(source):
    _, found = planned(source)
    assert not found.counted.any() and len(found) == 0 and found.filled_spheres == 0


def test_a_point_cloud_or_disabled_step_has_no_concavities():
    surface, _ = planned("primitive:mug", radius=BODY)
    off = encompass(surface, enabled=False)
    assert len(off.volume) == 0 and len(off) == 0
    cloud = SurfaceSamples(
        points=surface.points,
        normals=surface.normals,
        face_index=np.full(len(surface.points), -1),
        vertices=np.zeros((0, 3)),
        faces=np.zeros((0, 3), np.int64),
        spacing=surface.spacing,
        source="cloud",
        key="",
    )
    assert len(encompass(cloud).volume) == 0


def test_artefact_round_trip_and_determinism(tmp_path):
    surface, found = planned("primitive:mug", scale=0.5)
    found.save(tmp_path / "concavity.npz")
    loaded = Concavities.load(tmp_path / "concavity.npz")
    again = encompass(surface)
    for name in Concavities.ARRAYS:
        assert np.array_equal(getattr(loaded, name), getattr(found, name), equal_nan=True)
        assert np.array_equal(getattr(again, name), getattr(found, name), equal_nan=True), name
    assert loaded.key == found.key == again.key and loaded.filled_spheres == found.filled_spheres
    # at half size the 5 cm body fits ARMAR-III too
    assert found.counted.sum() == 1 and len(found.spheres_for(ARMAR3.max_graspable_diameter)) > 0


@pytest.mark.parametrize(
    "key, value, problem",
    [
        ("min_volume", 0.0, "concavity.min_volume must be in (0, 1)"),
        ("flat_mouth_deg", 90.0, "concavity.flat_mouth_deg must be in (0, 90)"),
        ("max_width_ratio", -1.0, "concavity.max_width_ratio must be > 0"),
    ],
)
def test_bad_concavity_params_are_one_line(key, value, problem):
    with pytest.raises(BadParamsError, match=problem.replace("(", r"\(").replace(")", r"\)")):
        ConcavityParams(**{key: value})


def test_recording_shows_the_concavities_and_their_spheres(tmp_path):
    from pipeline.outputs.recording import log_concavities, rerun_recording
    from test_recording import instances

    _, found = planned("primitive:mug", radius=BODY)
    path = tmp_path / "concavity.rrd"
    with rerun_recording(path, recording_id="mug") as stream:
        log_concavities(stream, "/mug", found)
    assert instances(path, "/mug/encompassing_spheres", "Ellipsoids3D:centers") == len(found)
    cup = int(np.flatnonzero(found.counted)[0])
    assert instances(path, f"/mug/concavities/{cup}", "Mesh3D:triangle_indices") == int((found.face_part == cup).sum())

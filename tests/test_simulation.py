"""Hands and grasp trials against known answers (paper IV; facts.md 4)."""

import dataclasses
import functools
import itertools
import pickle
import re
import threading

import numpy as np
import pandas as pd
import pytest

from pipeline.errors import BadParamsError
from pipeline.geometry.sampling import sample_object
from pipeline.hands.kinematics import base_poses
from pipeline.hands.spec import HANDS, export_hand, get_hand, load_hand
from pipeline.params import SampleParams
from pipeline.trial.engine import OUTCOMES, GraspEngine, object_mesh
from pipeline.trial.protocol import (
    CHUNK,
    TrialPool,
    baseline_candidates,
    chunks,
    run_trials,
    select_candidates,
    simulate,
    trial_rates,
)


@functools.lru_cache(maxsize=None)
def surface(source, **shape):
    return sample_object(
        source,
        scale=1.0,
        shape=shape or None,
        rng=np.random.default_rng(5),
        source_key=source,
        **dataclasses.asdict(SampleParams()),
    )


def cube():
    return surface("primitive:box", extents=(0.04, 0.04, 0.04))


def cylinder():
    return surface("primitive:cylinder", radius=0.025, height=0.12)


@functools.lru_cache(maxsize=None)
def world(name, object_name):
    return GraspEngine({"cube": cube, "cylinder": cylinder}[object_name](), HANDS[name])


def test_hands_declare_what_the_planner_needs():
    assert HANDS["armar3"].max_graspable_diameter == 0.094 and HANDS["barrett"].max_graspable_diameter == 0.14
    for hand in HANDS.values():
        assert "parallel" in hand.preshapes and hand.default_preshape == "parallel"
        assert abs(np.dot(hand.approach, hand.wrap)) < 1e-12
        for finger in hand.fingers:
            assert len(finger.joints) == len(finger.ratios) and all(j in hand.limits for j in finger.joints)
    barrett = HANDS["barrett"]
    assert [finger.ratios for finger in barrett.fingers] == [(1.0, 0.344)] * 3
    assert barrett.limits["f1_prox"] == (0.0, 2.44) and barrett.limits["f1_dist"] == (0.0, 0.84)
    assert HANDS["parallel_jaw"].limits["left_slide"] == (0.0, 0.04)  # 2 x 40 mm = the 80 mm stroke
    with pytest.raises(BadParamsError, match="unknown preshape 'pinch'"):
        barrett.preshape("pinch")


def test_hand_frame_maps_approach_and_wrap_onto_the_candidate():
    approach, orient = np.array([0.0, 0.6, 0.8]), np.array([1.0, 0.0, 0.0])
    for hand in HANDS.values():
        pose = base_poses(hand, np.array([[0.1, 0.2, 0.3]]), approach[None], orient[None])[0]
        rotation = pose[:3, :3]
        np.testing.assert_allclose(rotation @ hand.grasp_centre + pose[:3, 3], [0.1, 0.2, 0.3], atol=1e-12)
        np.testing.assert_allclose(rotation @ hand.approach, approach, atol=1e-12)
        np.testing.assert_allclose(rotation @ hand.wrap, orient, atol=1e-12)
        np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(rotation) == pytest.approx(1.0)


def test_parallel_jaw_on_a_cube_along_a_face_normal_is_force_closure():
    result = world("parallel_jaw", "cube").trial([0, 0, 0], [0, 0, -1], [1, 0, 0])
    assert result.outcome == "force_closure" and result.epsilon > 0
    # the open jaw (80 mm) clears the 40 mm cube at once, and comes on 3 mm until its palm,
    # placed 5 mm above the top face, is within the 2 mm tolerance of it
    assert (result.retract_m, result.approach_m) == (pytest.approx(-0.003, abs=1e-9), pytest.approx(0.003, abs=1e-9))
    assert "palm" in result.touched
    # each pad stops on its face: 40 mm - 20 mm = 20 mm of travel, within the 2 mm contact tolerance
    assert result.joint_positions == pytest.approx((0.02, 0.02), abs=0.002)
    assert set(result.touched) == {"palm", "left_pad", "right_pad"} and result.finger_stops == ("contact", "contact")
    pads = result.contact_links != 0
    np.testing.assert_allclose(np.abs(result.contact_points[pads, 1]), 0.02, atol=1e-7)  # on the two side faces
    np.testing.assert_allclose(np.abs(result.contact_normals[pads, 1]), 1.0, atol=1e-9)  # the faces' normals
    np.testing.assert_allclose(result.contact_points[~pads, 2], 0.02, atol=1e-7)  # the palm's on the top face


def test_barrett_on_a_cylinder_approached_orthogonally_is_force_closure():
    for angle in np.linspace(0, 2 * np.pi, 6, endpoint=False):
        approach = np.array([np.cos(angle), np.sin(angle), 0.0])
        result = world("barrett", "cylinder").trial([0, 0, 0.01], approach, [0, 0, 1])
        assert result.outcome == "force_closure", angle
        # every contact is on the cylinder's side, 25 mm from its axis
        np.testing.assert_allclose(np.hypot(*result.contact_points[:, :2].T), 0.025, atol=2e-4)


def test_barrett_distal_joint_follows_the_coupling_unless_its_proximal_link_stopped():
    barrett, checked = HANDS["barrett"], 0
    for angle, back in itertools.product(np.linspace(0, 2 * np.pi, 6, endpoint=False), (0.0, 0.05, 0.08)):
        approach = np.array([np.cos(angle), np.sin(angle), 0.0])
        # closing where placed (the retreat-only protocol), held farther out the cylinder meets
        # the distal links first
        bar = GraspEngine(cylinder(), barrett, approach_to_contact=False)
        result = bar.trial(np.array([0, 0, 0.01]) - back * approach, approach, [0, 0, 1])
        joints = dict(zip(barrett.limits, result.joint_positions))
        for prefix in ("f1", "f2", "f3"):
            proximal, distal = joints[f"{prefix}_prox"], joints[f"{prefix}_dist"]
            stopped = f"{prefix}_proximal" in result.touched
            assert stopped or distal == pytest.approx(0.344 * proximal, abs=1e-9)
            checked += not stopped
    assert checked >= 3
    # with nothing to grasp every finger closes to its limits, which the coupling matches:
    # 0.344 x 2.44 rad = 0.839 against the distal limit 0.84 (the stop blocks the proximal joint
    # as a contact would, and the distal closes the last 0.6 mrad on its own)
    free = GraspEngine(cube(), barrett, approach_to_contact=False).trial([1.0, 0, 0], [0, 0, -1], [1, 0, 0])
    assert free.outcome == "no_contact"
    joints = dict(zip(barrett.limits, free.joint_positions))
    for prefix in ("f1", "f2", "f3"):
        assert joints[f"{prefix}_prox"] == 2.44 and joints[f"{prefix}_dist"] == 0.84
        assert joints[f"{prefix}_dist"] == pytest.approx(0.344 * joints[f"{prefix}_prox"], abs=1e-3)


@pytest.mark.parametrize("name", sorted(HANDS))
def test_a_sphere_wider_than_the_hand_is_never_force_closure(name):
    # diameter 3 x the hand's limit: with exact contacts the Barrett (1.3 x) and ARMAR-III (2 x)
    # fingertips wrap far enough round a sphere wider than the paper's limit to close it
    # kinematically; whether such a grasp holds is the physics check's question (issue 15)
    radius = 1.5 * HANDS[name].max_graspable_diameter
    big = surface("primitive:sphere", radius=radius)
    bigworld = GraspEngine(big, HANDS[name])
    for approach in ([1, 0, 0], [0, 0, -1], [0, -0.6, 0.8]):
        approach = np.array(approach, float)
        orient = np.cross(approach, [0.3, 0.4, 0.5])
        result = bigworld.trial([0, 0, 0], approach, orient / np.linalg.norm(orient))
        assert result.outcome in ("no_force_closure", "collision", "no_contact")


def test_a_candidate_that_cannot_be_placed_is_an_error_row_and_the_others_run():
    engine = world("parallel_jaw", "cube")
    results = engine.run(
        [[0, 0, 0]] * 3, [[0, 0, -1], [0, 0, 0], [1, 0, 0]], [[1, 0, 0], [1, 0, 0], [1, 0, 0]], [None] * 3
    )
    assert [r.outcome for r in results][:2] == ["force_closure", "error"] and "P_d" in results[1].message
    assert results[2].outcome == "error"  # P_o along P_d


def test_a_hand_deep_inside_a_large_object_is_a_collision():
    slab = surface("primitive:box", extents=(0.6, 0.6, 0.6))
    result = GraspEngine(slab, HANDS["parallel_jaw"], retract_max_m=0.1).trial([0, 0, 0], [0, 0, -1], [1, 0, 0])
    assert result.outcome == "collision"


def test_exported_hand_loads_back_and_gives_the_same_trials(tmp_path):
    for name, hand in HANDS.items():
        spec = export_hand(hand, tmp_path / name)
        user = get_hand(str(spec))
        assert user.urdf and user.fingers == hand.fingers and user.limits == hand.limits
        assert user.preshapes == hand.preshapes and user.max_graspable_diameter == hand.max_graspable_diameter
        jaw = name in ("parallel_jaw", "franka")
        object_name = "cube" if jaw else "cylinder"
        target = ([0, 0, 0], [0, 0, -1], [1, 0, 0]) if jaw else ([0, 0, 0], [1, 0, 0], [0, 0, 1])
        mine = GraspEngine({"cube": cube, "cylinder": cylinder}[object_name](), user).trial(*target)
        theirs = world(name, object_name).trial(*target)
        assert (mine.outcome, mine.joint_positions) == (theirs.outcome, theirs.joint_positions)
        assert mine.epsilon == pytest.approx(theirs.epsilon, abs=1e-12)


@pytest.mark.parametrize(
    "edit, problem",
    [
        (lambda spec: spec.pop("fingers"), "lacks fingers"),
        (lambda spec: spec.update(urdf="missing.urdf"), "URDF 'missing.urdf' not found"),
        (lambda spec: spec.update(wrap=[0, 0, 1]), "orthogonal unit vectors"),
        (lambda spec: spec["preshapes"].update(parallel={"f1_prox": 9.0}), "outside its limits"),
        (lambda spec: spec.update(thumbs=2), "unknown key 'thumbs'"),
    ],
)
def test_bad_hand_specs_are_one_line_errors(tmp_path, edit, problem):
    import yaml

    path = export_hand(HANDS["barrett"], tmp_path)
    spec = yaml.safe_load(path.read_text())
    edit(spec)
    path.write_text(yaml.safe_dump(spec))
    with pytest.raises(BadParamsError, match=problem) as error:
        load_hand(path)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)
    with pytest.raises(BadParamsError, match="not found"):
        load_hand(tmp_path / "nothing.yaml")


def test_baseline_approaches_along_the_inward_normal_with_a_random_roll():
    samples = cylinder()
    table = baseline_candidates(samples, HANDS["barrett"], 200, np.random.default_rng(4))
    approach = table[["approach_x", "approach_y", "approach_z"]].to_numpy()
    orient = table[["orient_x", "orient_y", "orient_z"]].to_numpy()
    grasp = table[["grasp_x", "grasp_y", "grasp_z"]].to_numpy()
    index = [int(np.flatnonzero((samples.points == point).all(axis=1))[0]) for point in grasp]
    np.testing.assert_allclose(approach, -samples.normals[index], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(orient, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose((approach * orient).sum(axis=1), 0.0, atol=1e-12)
    assert table.equals(baseline_candidates(samples, HANDS["barrett"], 200, np.random.default_rng(4)))
    # rolls are spread: the orientation's angle about the approach is not one value
    assert np.ptp(np.arctan2(orient[:, 2], orient[:, 0])) > 3.0


def test_simulate_tables_summary_and_worker_independence():
    samples = cylinder()
    rows = []
    for sphere in range(6):  # axis spheres at z = -0.03 .. 0.02, four approaches each
        for angle in np.linspace(0, 2 * np.pi, 4, endpoint=False):
            rows.append(
                {
                    "hand": "barrett",
                    "id": sphere * 64 + len(rows) % 4,
                    "sphere_index": sphere,
                    "sphere_class": "axis",
                    "diameter_m": 0.05,
                    "preshape": "parallel",
                    "grasp_x": 0.0,
                    "grasp_y": 0.0,
                    "grasp_z": -0.03 + 0.01 * sphere,
                    "approach_x": np.cos(angle),
                    "approach_y": np.sin(angle),
                    "approach_z": 0.0,
                    "orient_x": 0.0,
                    "orient_y": 0.0,
                    "orient_z": 1.0,
                }
            )
    candidates = pd.DataFrame(rows)
    assert select_candidates(candidates, "barrett", 3, np.random.default_rng(1)).sphere_index.nunique() == 3
    trials, contacts = simulate(
        samples, candidates, [HANDS["barrett"]], spheres_per_object=3, baseline_trials=-1, seed=1, workers=1
    )
    assert (trials.planner == "mat").sum() == 12 == (trials.planner == "baseline").sum()
    assert set(trials.outcome.astype(str)) <= set(OUTCOMES) and not (trials.outcome == "error").any()
    assert (trials.outcome[trials.planner == "mat"] == "force_closure").all()
    assert (
        contacts.groupby("trial").size().reindex(range(len(trials)), fill_value=0).tolist() == trials.contacts.tolist()
    )
    result = trial_rates(trials[trials.planner == "mat"])
    assert result["force_closure_rate"] == 1.0 and result["outcomes"]["force_closure"] == 12
    assert result["mean_epsilon"] == pytest.approx(trials.epsilon[trials.planner == "mat"].mean())
    again, again_contacts = simulate(
        samples, candidates, [HANDS["barrett"]], spheres_per_object=3, baseline_trials=-1, seed=1, workers=2
    )
    pd.testing.assert_frame_equal(trials, again)
    pd.testing.assert_frame_equal(contacts, again_contacts)


def test_chunks_cover_every_trial_once_a_hands_tables_together_each_a_sample_of_them_with_workers():
    hands, lengths = [0, 1, 0, 0], [1300, 0, 70, 5]  # trials 0-1299, 1300-1369 and 1370-1374
    for workers in (1, 2, 3):
        found = list(chunks(hands, lengths, workers))
        assert sorted(int(trial) for _, trials in found for trial in trials) == list(range(1375))
        assert all(hand == 0 for hand, _ in found)
        # the hand's 1,375 trials in as few chunks as CHUNK and the workers allow, a multiple of
        # the workers, each one of every count trials in a row: sizes differ by one at most
        count = workers * -(-1375 // (workers * CHUNK))
        sizes = [len(trials) for _, trials in found]
        assert len(found) == count and max(sizes) <= CHUNK and max(sizes) - min(sizes) <= 1
        assert all((np.bincount(trials // count) == 1)[:-1].all() for _, trials in found)
    # rows of a kind recurring every 2 or 4 (a rim sphere's P_o and -P_o, rows 2m and 2m + 1)
    # spread evenly over the chunks: every count-th trial gave each chunk of 820 trials on two
    # workers 410 of one kind and none of the other
    for workers, trials in ((2, 820), (2, 3000), (3, 2400), (4, 5000)):
        for _, chunk in chunks([0], [trials], workers):
            for period in (2, 4):
                assert (np.abs(np.bincount(chunk % period, minlength=period) - len(chunk) / period) <= 2).all()
    # two hands, 70 and 40 trials, two workers: two chunks each, the second hand's numbered on
    assert [(hand, len(trials), int(trials[0])) for hand, trials in chunks([0, 1], [70, 40], 2)] == [
        (0, 35, 0),
        (0, 35, 1),
        (1, 20, 70),
        (1, 20, 71),
    ]


def test_run_trials_keeps_table_order_across_workers():
    # 70 + 40 rows in two chunks each with two processes: this one and a worker share them
    tables = [
        (0, baseline_candidates(cube(), HANDS["parallel_jaw"], 70, np.random.default_rng(2))),
        (1, baseline_candidates(cube(), HANDS["barrett"], 40, np.random.default_rng(3))),
    ]
    hands = [HANDS["parallel_jaw"], HANDS["barrett"]]
    assert len(list(chunks([0, 1], [70, 40], 2))) > 2
    serial = run_trials(cube(), hands, tables, None, workers=1)
    parallel = run_trials(cube(), hands, tables, None, workers=2)
    for one, other in zip(serial, parallel):
        assert [r.outcome for r in one] == [r.outcome for r in other]
        assert [r.epsilon for r in one] == [r.epsilon for r in other]
        assert [r.joint_positions for r in one] == [r.joint_positions for r in other]


def test_kernel_cache_loads_the_engines_kernels_in_a_new_process():
    import subprocess
    import sys

    GraspEngine(cube(), HANDS["parallel_jaw"]).trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0])  # cached
    code = (
        "import pipeline.kernel_cache as cache, pipeline.trial.proximity as proximity; "
        "print(cache.LOADED, len(proximity._feature_hits.overloads))"
    )
    loaded, feature_kernels = map(int, subprocess.check_output([sys.executable, "-c", code], text=True).split())
    assert loaded >= 10 and feature_kernels >= 1  # before any call


def _imported_before_any_work():
    import sys

    return [name in sys.modules for name in ("pipeline.trial.engine", "open3d", "trimesh")]


def test_trial_workers_start_with_the_engine_already_imported():
    import concurrent.futures

    from pipeline import pool

    pool.start()
    with concurrent.futures.ProcessPoolExecutor(1, pool.context()) as executor:
        assert executor.submit(_imported_before_any_work).result() == [True, True, True]


def test_hand_pictures_show_the_hand_open_and_closed_on_the_object(tmp_path):
    from PIL import Image

    from pipeline.outputs.render import closed_joints, render_open_closed

    closed = closed_joints(HANDS["barrett"])
    assert closed["f1_prox"] == 2.44 and closed["f1_dist"] == pytest.approx(0.344 * 2.44)
    path = render_open_closed(
        HANDS["barrett"],
        tmp_path / "barrett.png",
        surface=cylinder(),
        target=([0, 0, 0.01], [1, 0, 0], [0, 0, 1]),
        size=(120, 100),
    )
    image = np.asarray(Image.open(path))
    assert image.shape == (100, 240, 3)
    open_half, closed_half = image[:, :120].astype(int), image[:, 120:].astype(int)
    orange = (image[..., 0] > 150) & (image[..., 2] < 120)  # the object's colour
    assert orange[:, :120].sum() > 100 and orange[:, 120:].sum() > 100
    assert np.abs(open_half - closed_half).sum(axis=2).astype(bool).mean() > 0.02  # the fingers moved


def test_a_toml_hand_spec_reads_like_the_yaml_one(tmp_path):
    import yaml

    spec = yaml.safe_load(export_hand(HANDS["parallel_jaw"], tmp_path).read_text())

    def toml_value(value):
        if isinstance(value, dict):
            return "{" + ", ".join(f"{key} = {toml_value(item)}" for key, item in value.items()) + "}"
        if isinstance(value, list):
            return "[" + ", ".join(toml_value(item) for item in value) + "]"
        return f'"{value}"' if isinstance(value, str) else repr(value)

    (tmp_path / "jaw.toml").write_text("".join(f"{key} = {toml_value(value)}\n" for key, value in spec.items()))
    assert load_hand(tmp_path / "jaw.toml") == load_hand(tmp_path / "parallel_jaw.yaml")
    (tmp_path / "broken.toml").write_text("name = \n")
    with pytest.raises(BadParamsError, match="not valid TOML"):
        load_hand(tmp_path / "broken.toml")


def test_an_object_without_candidates_gives_empty_tables(tmp_path):
    from pipeline.artefacts import read_table, write_table
    from pipeline.geometry.candidates import COLUMNS

    empty = pd.DataFrame({column: [] for column in COLUMNS})
    trials, contacts = simulate(cube(), empty, [HANDS["barrett"]], spheres_per_object=5, baseline_trials=-1)
    assert len(trials) == 0 and len(contacts) == 0 and {"outcome", "epsilon", "planner"} <= set(trials.columns)
    assert trial_rates(trials)["trials"] == 0 and np.isnan(trial_rates(trials)["force_closure_rate"])
    write_table(tmp_path / "trials.parquet", trials)
    assert len(read_table(tmp_path / "trials.parquet")) == 0


def test_run_trials_builds_the_objects_grid_once_for_every_hand_and_worker(monkeypatch):
    from pipeline.trial import protocol

    built = []
    monkeypatch.setattr(protocol, "object_mesh", lambda *args: built.append(1) or object_mesh(*args))
    tables = [
        (0, baseline_candidates(cube(), HANDS["parallel_jaw"], 30, np.random.default_rng(2))),
        (1, baseline_candidates(cube(), HANDS["barrett"], 30, np.random.default_rng(3))),
    ]
    results = run_trials(cube(), [HANDS["parallel_jaw"], HANDS["barrett"]], tables, None, workers=2)
    assert len(built) == 1 and [len(rows) for rows in results] == [30, 30]
    assert run_trials(cube(), [HANDS["barrett"]], [(0, tables[1][1].iloc[:0])], None) == [[]]
    assert len(built) == 1  # no rows: no grid


def test_a_worker_killed_mid_run_is_one_clear_error_not_a_broken_pool(monkeypatch):
    import multiprocessing
    import os
    import signal

    from pipeline.errors import PipelineError, WorkerError
    from pipeline.trial import protocol

    monkeypatch.setattr(protocol, "CHUNK", 4)  # 64 rows in 16 chunks: most still to run at the kill
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 64, np.random.default_rng(2))
    killed = []

    def kill_the_workers(finished, total):  # as the system does when memory runs out
        if not killed:
            killed.extend(child.pid for child in multiprocessing.active_children())
            for pid in killed:
                os.kill(pid, signal.SIGKILL)

    with pytest.raises(
        WorkerError,
        match=re.escape(cube().source) + ": a trial worker process ended abruptly.*64 trials.*fewer workers",
    ) as raised:
        run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2, progress=kill_the_workers)
    assert killed and isinstance(raised.value, PipelineError)  # a stage prints it as one line


def _die(*_):
    import os
    import signal

    os.kill(os.getpid(), signal.SIGKILL)  # as the system does when memory runs out


def test_a_worker_killed_while_it_computes_the_grid_is_the_same_clear_error(monkeypatch):
    from pipeline.errors import WorkerError
    from pipeline.trial import protocol

    monkeypatch.setattr(protocol, "grid_distances", _die)  # the first worker's task
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 8, np.random.default_rng(2))
    with pytest.raises(
        WorkerError, match=re.escape(cube().source) + ": a trial worker process ended abruptly.*8 trials"
    ):
        run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2)


def test_the_grid_a_worker_computes_is_the_one_the_object_mesh_computes_bit_for_bit():
    from pipeline.geometry.mesh_query import ObjectMesh, grid_distances

    duck = surface("pybullet:duck.obj")
    own = ObjectMesh(duck.vertices, duck.faces)
    given = ObjectMesh(duck.vertices, duck.faces, grid=lambda: grid_distances(duck.vertices, duck.faces, 40))
    assert own.grid.shape == given.grid.shape and (own.grid < 0).any() and (own.grid > 0).any()
    assert np.array_equal(own.grid.view(np.uint64), given.grid.view(np.uint64))
    assert np.array_equal(own.origin, given.origin) and own.voxel == given.voxel


def test_the_workers_started_before_the_engines_are_built_do_not_outlive_a_failed_build(monkeypatch):
    from pipeline.errors import BadInputError
    from pipeline.trial import protocol

    def broken_mesh(surface, settings, grid=None):  # the workers are started by now, waiting for the engines
        raise BadInputError(f"{surface.source}: broken")

    monkeypatch.setattr(protocol, "object_mesh", broken_mesh)
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 8, np.random.default_rng(2))
    raised = []

    def run():
        try:
            run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2)
        except BadInputError as error:
            raised.append(error)

    running = threading.Thread(target=run, daemon=True)
    running.start()
    running.join(timeout=60)
    assert not running.is_alive(), "run_trials hung on its workers after the engines' build failed"
    assert [str(error) for error in raised] == [f"{cube().source}: broken"]


def test_the_workers_copy_of_the_engines_is_removed_once_they_end(monkeypatch):
    import os
    import tempfile

    from pipeline.trial import protocol

    written, mkstemp = [], tempfile.mkstemp

    def recorded(**names):
        written.append(mkstemp(**names))
        return written[-1]

    monkeypatch.setattr(protocol.tempfile, "mkstemp", recorded)
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 8, np.random.default_rng(2))
    results = run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2)
    assert [len(rows) for rows in results] == [8]
    for closing in [thread for thread in threading.enumerate() if thread.name == "close trial pool"]:
        closing.join(timeout=60)
    assert len(written) == 1 and not os.path.exists(written[0][1])


def _outcomes(results):
    return [[(r.outcome, r.epsilon, r.joint_positions) for r in rows] for rows in results]


def test_a_kept_pools_workers_run_each_call_with_that_calls_engines(monkeypatch, tmp_path):
    import os

    from pipeline.trial import protocol

    # every call's engines in a file of the same name, as a freed temporary name may come again:
    # a worker must still load each call's own
    path = str(tmp_path / "engines.pickle")
    monkeypatch.setattr(protocol.tempfile, "mkstemp", lambda **_: (os.open(path, os.O_CREAT | os.O_WRONLY), path))
    calls = [
        (
            [HANDS["parallel_jaw"]],
            [(0, baseline_candidates(cube(), HANDS["parallel_jaw"], 6, np.random.default_rng(4)))],
        ),
        ([HANDS["barrett"]], [(0, baseline_candidates(cube(), HANDS["barrett"], 6, np.random.default_rng(5)))]),
        (
            [HANDS["parallel_jaw"]],
            [(0, baseline_candidates(cube(), HANDS["parallel_jaw"], 6, np.random.default_rng(6)))],
        ),
    ]
    serial = [run_trials(cube(), hands, tables, None) for hands, tables in calls]
    for caller_has_kernels in (True, False):  # the caller runs a chunk of each call, or none
        monkeypatch.setattr(protocol, "kernels_loaded", lambda: caller_has_kernels)
        with TrialPool() as kept:
            found, executors = [], []
            for hands, tables in calls:
                timeline = []
                found.append(run_trials(cube(), hands, tables, None, workers=2, pool=kept, timeline=timeline))
                assert {process for step, process, _, _ in timeline if step == "chunk"} == (
                    {0, 1} if caller_has_kernels else {1, 2}
                )
                assert not os.path.exists(path)  # removed once the call's chunks have run
                executors.append(kept.executor(1))
            assert all(executor is executors[0] for executor in executors)  # the same worker processes
        assert [_outcomes(results) for results in found] == [_outcomes(results) for results in serial]


def test_a_worker_killed_in_a_kept_pool_is_the_clear_error_and_the_next_call_starts_new_ones(monkeypatch):
    from pipeline.errors import WorkerError
    from pipeline.trial import protocol

    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 8, np.random.default_rng(2))
    with TrialPool() as kept:
        with monkeypatch.context() as patched:
            patched.setattr(protocol, "grid_distances", _die)  # the first worker's task
            with pytest.raises(WorkerError, match="a trial worker process ended abruptly.*8 trials"):
                run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2, pool=kept)
        results = run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2, pool=kept)
    assert _outcomes(results) == _outcomes(run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None))


def _freeze_count():
    import gc

    return gc.get_freeze_count()


def test_a_pool_worker_keeps_its_start_out_of_the_garbage_collectors_full_passes(tmp_path):
    import concurrent.futures

    from pipeline import pool
    from pipeline.trial.engine import start_pool_worker

    pool.start()
    with concurrent.futures.ProcessPoolExecutor(1, pool.context(), initializer=start_pool_worker) as executor:
        assert executor.submit(_freeze_count).result() > 10_000  # numpy's, open3d's, the engine's objects


def test_a_pool_worker_runs_every_built_in_hand_without_importing_trimesh(tmp_path):
    import concurrent.futures

    from pipeline import pool
    from pipeline.arrays import vectors
    from pipeline.trial.engine import start_pool_worker
    from worker_probe import trials_and_trimesh

    # the fork server leaves trimesh out (0.4 s of its start): a worker must never need it
    hands = list(HANDS.values())
    (tmp_path / "engines.pickle").write_bytes(
        pickle.dumps({number: GraspEngine(cube(), hand) for number, hand in enumerate(hands)})
    )
    pool.start()
    copy = (str(tmp_path / "engines.pickle"), 0)
    with concurrent.futures.ProcessPoolExecutor(1, pool.context(), initializer=start_pool_worker) as executor:
        for number, hand in enumerate(hands):
            table = baseline_candidates(cube(), hand, 2, np.random.default_rng(number))
            targets = [vectors(table, name) for name in ("grasp", "approach", "orient")]
            outcomes, imported = executor.submit(
                trials_and_trimesh, copy, number, *targets, list(table.preshape)
            ).result()
            assert len(outcomes) == 2 and set(outcomes) <= set(OUTCOMES) and not imported, hand.name


def test_a_pool_worker_grades_on_one_blas_thread_without_starting_blas_helpers():
    import concurrent.futures
    import os

    from pipeline import pool
    from pipeline.trial.engine import start_pool_worker
    from worker_probe import blas_threads_and_threads_gained

    before = os.environ.get("OPENBLAS_NUM_THREADS")
    pool.start()
    assert os.environ.get("OPENBLAS_NUM_THREADS") == before  # the caller's environment as it was
    with concurrent.futures.ProcessPoolExecutor(1, pool.context(), initializer=start_pool_worker) as executor:
        counts, gained = executor.submit(blas_threads_and_threads_gained).result()
    # numpy's and scipy's OpenBLAS, each on one thread; a worker forked from a server whose
    # OpenBLAS had helpers would start them anew here (one per other CPU, each spinning 0.1 s)
    assert counts and set(counts) == {1} and gained == 0


def test_run_trials_keeps_the_callers_objects_out_of_the_collectors_passes_while_it_runs():
    assert _freeze_count() == 0, "the test process froze objects before the test"
    counts = []
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 4, np.random.default_rng(3))
    run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, progress=lambda *_: counts.append(_freeze_count()))
    # the test process's objects while the trials ran (pipeline/allocator.py's test shows what
    # freezing does); afterwards, back in the collector's reach
    assert counts and min(counts) > 10_000 and _freeze_count() == 0


def test_the_timeline_shows_each_chunk_where_it_ran_after_the_engines_it_needed(monkeypatch):
    from pipeline.trial import protocol

    monkeypatch.setattr(protocol, "kernels_loaded", lambda: True)  # a caller that has run trials
    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 6, np.random.default_rng(4))
    timeline = []
    run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2, timeline=timeline)
    spans = {}
    for step, process, start, end in timeline:
        assert start <= end
        spans.setdefault(step, []).append((process, start, end))
    (call,) = spans["call"]
    (forking,) = spans["start workers"]
    (setup,) = spans["set-up"]
    (ship,) = spans["ship"]
    assert forking[1] == call[1] and forking[2] == setup[1] and setup[2] == ship[1]
    # two chunks of three rows, one in each process, once the engines are built; the worker's
    # begins once their copy is shipped to it (the clock is the machine's) and its results come
    # back after it ends
    assert sorted(process for process, _, _ in spans["chunk"]) == [0, 1]
    assert all(start >= setup[2] and end <= call[2] for _, start, end in spans["chunk"])
    (worker,) = [span for span in spans["chunk"] if span[0] == 1]
    (back,) = spans["results"]
    assert worker[1] >= ship[1] and back[0] == 1 and back[1] == worker[2] and back[2] <= call[2]


def test_a_caller_without_the_kernels_leaves_every_chunk_to_as_many_workers(monkeypatch):
    from pipeline.trial import protocol

    table = baseline_candidates(cube(), HANDS["parallel_jaw"], 6, np.random.default_rng(4))
    serial = run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=1)
    monkeypatch.setattr(protocol, "kernels_loaded", lambda: False)  # a stage's fresh process
    timeline = []
    results = run_trials(cube(), [HANDS["parallel_jaw"]], [(0, table)], None, workers=2, timeline=timeline)
    # the same two chunks of three rows, one in each of two workers, none here
    ran = sorted((process, end) for step, process, _, end in timeline if step == "chunk")
    assert [process for process, _ in ran] == [1, 2]
    (setup,) = [(start, end) for step, _, start, end in timeline if step == "set-up"]
    assert all(end >= setup[1] for _, end in ran)
    assert [(r.outcome, r.epsilon, r.joint_positions) for r in results[0]] == [
        (r.outcome, r.epsilon, r.joint_positions) for r in serial[0]
    ]


def test_a_process_has_the_kernels_once_it_has_run_a_trial_not_before():
    import subprocess
    import sys

    code = (
        "import pickle, sys; from pipeline.hands.spec import HANDS; "
        "from pipeline.trial.engine import GraspEngine, kernels_loaded; "
        "engine, before = GraspEngine(pickle.load(sys.stdin.buffer), HANDS['parallel_jaw']), kernels_loaded(); "
        "engine.trial([0.0, 0.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]); print(before, kernels_loaded())"
    )
    found = subprocess.run([sys.executable, "-c", code], input=pickle.dumps(cube()), capture_output=True, check=True)
    assert found.stdout.split() == [b"False", b"True"]


def test_an_engines_process_and_a_pool_worker_keep_freed_memory(monkeypatch, tmp_path):
    from pipeline.trial import engine

    calls = []
    monkeypatch.setattr(engine, "keep_freed_memory", lambda: calls.append(True))
    monkeypatch.setattr(engine.gc, "freeze", lambda: None)  # not this test process's objects
    engine.GraspEngine(cube(), HANDS["parallel_jaw"])
    engine.start_pool_worker()
    assert len(calls) == 2  # pipeline/allocator.py's test shows what it does

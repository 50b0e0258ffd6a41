"""Batch planning on an embedded Ray (slow: each Ray start takes seconds; run in CI)."""

import dataclasses
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml

from conftest import complete_params
from pipeline.batch import find_meshes, plan_object, read_results, run_batch
from pipeline.checks.protocol import with_checks
from pipeline.errors import BadInputError
from pipeline.params import load_params
from pipeline.plan import run_chain

REPO = Path(__file__).resolve().parents[1]
HANDS = ["barrett"]
SCALE = 0.015  # the scale of pybullet's random_urdfs, as their URDFs give it
PARAMS = complete_params(
    {
        "seed": 0,
        "sample": {"count": 2000},
        "simulate": {"spheres_per_object": 2, "baseline_trials": 2},
        "checks": {"trials": 3, "robust_samples": 2, "vhacd_resolution": 100000},
    }
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """Nine of pybullet's random objects and one corrupt mesh, with a small params file."""
    import pybullet_data

    folder = tmp_path_factory.mktemp("dataset")
    (folder / "meshes").mkdir()
    source = Path(pybullet_data.getDataPath()) / "random_urdfs"
    for number in range(9):
        shutil.copy(source / f"{number:03d}" / f"{number:03d}.obj", folder / "meshes")
    (folder / "meshes" / "corrupt.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
    (folder / "params.yaml").write_text(yaml.safe_dump(PARAMS))
    return folder, load_params(folder / "params.yaml")


@pytest.fixture(scope="module")
def finished(dataset):
    folder, params = dataset
    counts = run_batch(
        find_meshes(folder / "meshes"), folder / "out", hands=HANDS, params=params, scale=SCALE, workers=2
    )
    return counts, *read_results(folder / "out")


def row_of(objects, name):
    return objects[objects.object == name].iloc[0]


def test_batch_rows_match_plan_and_the_corrupt_mesh_is_one_error_row(dataset, finished):
    folder, params = dataset
    counts, objects, trials = finished
    assert counts == {**counts, "ok": 9, "error": 1, "failed": 0, "skipped": 0}
    assert sorted(objects.object) == sorted([f"{number:03d}" for number in range(9)] + ["corrupt"])
    error = objects[objects.status == "error"]
    assert error.object.tolist() == ["corrupt"] and "corrupt.obj" in error.reason.iloc[0]
    assert set(trials.object) == set(objects.object[objects.status == "ok"])
    for name in objects.object[objects.status == "ok"]:
        artefacts, _ = run_chain(
            str(folder / "meshes" / f"{name}.obj"), params, scale=SCALE, seed=0, hands=HANDS, simulate=True, workers=1
        )
        mine = trials[trials.object == name].drop(columns="object").reset_index(drop=True)
        expected = with_checks(artefacts["trials"], artefacts["check"])  # each trial with its checks
        pd.testing.assert_frame_equal(mine, expected, check_categorical=False)
        checks = artefacts["check"][artefacts["check"].planner == "mat"]
        assert mine.physics_success.notna().sum() == len(artefacts["check"]) > 0
        assert row_of(objects, name).physics_success_rate == pytest.approx(checks.physics_success.mean())
        row = row_of(objects, name)
        assert row.candidates == len(artefacts["candidates"]) and row.medial_spheres == len(artefacts["mat"])


def test_a_rerun_on_a_finished_output_skips_every_object_without_ray(dataset, finished):
    import ray

    folder, params = dataset
    before = {path.name: path.stat().st_mtime_ns for path in (folder / "out").rglob("*.parquet")}
    counts = run_batch(
        find_meshes(folder / "meshes"), folder / "out", hands=HANDS, params=params, scale=SCALE, workers=2
    )
    assert counts["skipped"] == 10 and counts["ok"] == counts["error"] == counts["failed"] == 0
    assert counts["ray_start_s"] == 0 and not ray.is_initialized()
    assert {path.name: path.stat().st_mtime_ns for path in (folder / "out").rglob("*.parquet")} == before


def test_a_killed_batch_resumes_with_no_duplicated_or_missing_rows(dataset, finished, tmp_path):
    folder, params = dataset
    _, objects, trials = finished
    command = [
        sys.executable,
        "-m",
        "pipeline",
        "batch",
        str(folder / "meshes"),
        "--hand",
        HANDS[0],
        "--out",
        str(tmp_path / "out"),
        "--workers",
        "2",
        "--scale",
        str(SCALE),
        "--params",
        str(folder / "params.yaml"),
    ]
    driver = subprocess.Popen(
        command,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    while len(list((tmp_path / "out" / "objects").glob("*.parquet"))) < 3 and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(driver.pid, signal.SIGKILL)  # the driver and the Ray it started
    driver.wait()
    written = len(list((tmp_path / "out" / "objects").glob("*.parquet")))
    assert 3 <= written < 10, "the batch was not interrupted midway"

    counts = run_batch(
        find_meshes(folder / "meshes"), tmp_path / "out", hands=HANDS, params=params, scale=SCALE, workers=2
    )
    assert counts["skipped"] == written and counts["ok"] + counts["error"] == 10 - written
    resumed, resumed_trials = read_results(tmp_path / "out")
    assert sorted(resumed.object) == sorted(objects.object)  # each object once
    key = ["object", "planner", "candidate_id"]
    pd.testing.assert_frame_equal(
        resumed_trials.sort_values(key).reset_index(drop=True),
        trials.sort_values(key).reset_index(drop=True),
        check_categorical=False,
    )


def test_a_worker_crash_is_retried_once_then_recorded(dataset, tmp_path):
    folder, params = dataset
    attempts = tmp_path / "attempts"
    attempts.mkdir()

    def crashing(name, path, **keywords):  # pickled by value: the Ray workers run it as it is
        if name == "001":
            (attempts / f"{os.getpid()}").touch()
            os._exit(1)
        if name == "002":
            raise AssertionError()  # an exception without a message
        return plan_object(name, path, **keywords)

    meshes = [(name, path) for name, path in find_meshes(folder / "meshes") if name in ("000", "001", "002")]
    counts = run_batch(meshes, tmp_path / "out", hands=HANDS, params=params, scale=SCALE, workers=2, task=crashing)
    objects, _ = read_results(tmp_path / "out")
    assert counts == {**counts, "ok": 1, "failed": 2} and len(list(attempts.iterdir())) == 2  # first try + one retry
    reasons = dict(zip(objects.object, objects.reason))
    assert reasons["001"].startswith("WorkerCrashedError (after one retry)") and reasons["002"] == "AssertionError: "
    # failed objects run again next time; done ones are skipped
    again = run_batch(meshes, tmp_path / "out", hands=HANDS, params=params, scale=SCALE, workers=2)
    assert again["skipped"] == 1 and again["ok"] == 2


def test_an_object_too_big_for_the_hand_has_no_trials_file_and_no_rate(dataset):
    folder, params = dataset
    params = dataclasses.replace(params, simulate=dataclasses.replace(params.simulate, baseline_trials=-1))
    row, trials = plan_object("000", folder / "meshes" / "000.obj", scale=0.45, seed=0, hands=HANDS, params=params)
    assert trials is None and row["status"] == "ok" and row["candidates"] == 0 == row["mat_trials"]  # 3.6 m long
    assert row["baseline_trials"] == 0  # as many as the MAT trials
    assert math.isnan(row["force_closure_rate"]) and math.isnan(row["baseline_force_closure_rate"])  # no rate, not 0


def test_the_same_command_joins_a_running_cluster(dataset, finished, tmp_path):
    folder, _ = dataset
    ray = [str(Path(sys.executable).parent / "ray")]
    env = {**os.environ, "PYTHONPATH": str(REPO), "RAY_USAGE_STATS_ENABLED": "0", "RAY_AUTH_MODE": "disabled"}
    started = subprocess.run(
        ray
        + [
            "start",
            "--head",
            "--port",
            "6391",
            "--num-cpus",
            "2",
            "--include-dashboard=false",
            "--disable-usage-stats",
        ],
        env=env,
        capture_output=True,
        text=True,
    )
    assert started.returncode == 0, started.stderr
    try:
        joined = subprocess.run(
            [
                sys.executable,
                "-m",
                "pipeline",
                "batch",
                str(folder / "meshes"),
                "--hand",
                HANDS[0],
                "--out",
                str(tmp_path / "out"),
                "--scale",
                str(SCALE),
                "--params",
                str(folder / "params.yaml"),
                "--address",
                "127.0.0.1:6391",
            ],
            cwd=tmp_path,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
    finally:
        subprocess.run(ray + ["stop"], env=env, capture_output=True)
    assert joined.returncode == 0, joined.stderr
    assert "9 ok, 1 bad meshes, 0 failed" in joined.stdout
    _, objects, trials = finished
    mine, my_trials = read_results(tmp_path / "out")
    assert sorted(mine.object) == sorted(objects.object)
    key = ["object", "planner", "candidate_id"]
    pd.testing.assert_frame_equal(
        my_trials.sort_values(key).reset_index(drop=True),
        trials.sort_values(key).reset_index(drop=True),
        check_categorical=False,
    )


def test_find_meshes_names_by_stem_or_path_and_refuses_a_name_clash(tmp_path):
    for relative in ("b/2.obj", "b/10.obj", "a/2.obj", "notes.txt"):
        (tmp_path / relative).parent.mkdir(exist_ok=True)
        (tmp_path / relative).write_text("")
    assert [name for name, _ in find_meshes(tmp_path)] == ["a_2", "b_2", "b_10"]  # stems clash: relative paths
    (tmp_path / "a" / "_base.obj").write_text("")
    assert [name for name, _ in find_meshes(tmp_path / "a")] == ["2", "mesh_base"]  # parquet readers skip _* files
    assert all(path.is_absolute() for _, path in find_meshes(tmp_path))
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "x y.obj").write_text("")
    (tmp_path / "c" / "x_y.stl").write_text("")
    with pytest.raises(BadInputError, match="object name 'c_x_y'"):
        find_meshes(tmp_path / "c" / "..")

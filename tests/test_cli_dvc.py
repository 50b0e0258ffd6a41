"""End to end: `python -m pipeline plan` and `dvc repro` caching (slow, run in CI)."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from conftest import complete_params
from pipeline import dag
from pipeline.artefacts import MedialSpheres
from pipeline.checks.protocol import with_checks
from pipeline.geometry.objects import load_source
from pipeline.geometry.symmetry import Symmetry
from pipeline.logbook import file_digest, read_log
from test_recording import instances, rows_of

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO), "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}


def run(args, cwd):
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=ENV)


@pytest.mark.slow
def test_plan_writes_every_artefact_and_summary(tmp_path):
    (tmp_path / "params.yaml").write_text(
        yaml.safe_dump(complete_params({"sample": {"count": 3000}, "checks": {"trials": 3, "robust_samples": 4}}))
    )
    plan = [
        sys.executable,
        "-m",
        "pipeline",
        "plan",
        "primitive:box",
        "--seed",
        "3",
        "--params",
        "params.yaml",
        "--spheres",
        "3",
        "--baseline",
        "4",
        "--workers",
        "1",
    ]
    result = run(plan + ["--out", "out"], tmp_path)
    assert result.returncode == 0, result.stderr
    names = {path.name for path in (tmp_path / "out").iterdir()}
    assert names == {
        "surface.npz",
        "medial_axis.npz",
        "spheres.npz",
        "sphere_grid.npz",
        "symmetry.npz",
        "concavity.npz",
        "candidates.parquet",
        "trials.parquet",
        "contacts.parquet",
        "parts.npz",
        "checks.parquet",
        "summary.json",
    }
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["counts"]["surface_samples"] == 3000 and summary["seed"] == 3
    assert set(summary["timings_s"]) == {stage.name for stage in dag.STAGES}
    trials = pd.read_parquet(tmp_path / "out" / "trials.parquet")
    mat = trials[trials.planner == "mat"]
    assert summary["trials"] == len(mat) > 0 and summary["baseline"]["trials"] == 2 * 4
    assert sum(summary["outcomes"].values()) == len(mat)
    assert summary["force_closure_rate"] == (mat.outcome == "force_closure").mean()
    for hand in ("armar3", "barrett"):  # at most 3 spheres per hand, all their candidates
        assert mat[mat.hand == hand].sphere_index.nunique() <= 3
    table = pd.read_parquet(tmp_path / "out" / "candidates.parquet")
    assert summary["candidates"] == {hand: int((table.hand == hand).sum()) for hand in ("armar3", "barrett")}
    assert sum(summary["classes"].values()) == len(np.load(tmp_path / "out" / "symmetry.npz")["class_id"])
    # the checks: params checks.trials (3 here) per hand and planner, the physics check on the closed hands
    checks = pd.read_parquet(tmp_path / "out" / "checks.parquet")
    assert checks.groupby(["hand", "planner"]).size().max() <= 3 and len(checks) > 0
    closed = checks.outcome.isin(["force_closure", "no_force_closure"])
    assert (checks.physics_outcome[~closed] == "no_grasp").all() and checks.physics_slip_m[~closed].isna().all()
    assert (
        checks.robust_fc.between(0, 1).all() and summary["checks"]["mat"]["checked"] == (checks.planner == "mat").sum()
    )
    # the same seed gives the same artefacts (the checks too, with another worker count)
    again = run(plan[:-1] + ["2", "--out", "again"], tmp_path)
    assert again.returncode == 0
    for name in (
        "surface.npz",
        "spheres.npz",
        "sphere_grid.npz",
        "symmetry.npz",
        "candidates.parquet",
        "trials.parquet",
        "contacts.parquet",
        "parts.npz",
        "checks.parquet",
    ):
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / "again" / name).read_bytes()


@pytest.mark.slow
def test_plan_on_bad_mesh_is_one_line(tmp_path):
    (tmp_path / "broken.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    result = run([sys.executable, "-m", "pipeline", "plan", "broken.obj", "--out", "out"], tmp_path)
    assert result.returncode == 2 and result.stderr.startswith("error: broken.obj")
    assert result.stderr.count("\n") == 1 and not (tmp_path / "out").exists()
    unknown = run(
        [sys.executable, "-m", "pipeline", "plan", "primitive:box", "--hand", "shadow", "--out", "out"], tmp_path
    )
    assert (
        unknown.returncode == 2
        and unknown.stderr
        == "error: unknown hand 'shadow' (built-in: armar3, barrett, parallel_jaw, franka; or a spec .yaml/.toml)\n"
    )
    assert not (tmp_path / "out").exists()


def test_report_on_an_object_without_stage_files_says_to_write_them(tmp_path):
    # params.yaml gained an object but `python -m pipeline.dag` did not run: DVC has no stage of it
    params = complete_params({})
    params["objects"] = {"newcomer": {"source": "primitive:box"}}
    params["report"]["figure_objects"] = []
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    result = run([sys.executable, "-m", "stages.report", "data", "report"], tmp_path)
    assert result.returncode == 2 and result.stderr == (
        "error: params.yaml: object 'newcomer' has no stage files; run `python -m pipeline.dag` to write them "
        "(make run does), then `dvc repro`\n"
    )
    assert not (tmp_path / "report").exists()


TINY_OBJECTS, TINY_SCALES, TINY_HANDS = ("capsule",), (1.0, 0.5), ("armar3", "barrett")
TINY_RUNS = [(name, scale, hand) for name in TINY_OBJECTS for scale in TINY_SCALES for hand in TINY_HANDS]


def tiny_project(tmp_path):
    """A copy of the project with the tiny config: 1 object x 2 scales x 2 hands, 5 spheres."""
    for name in ("pipeline", "stages", "dag", "dvc.yaml"):
        source = REPO / name
        if source.is_dir():
            # numba's compiled kernels (__pycache__/*.nbi, *.nbc) come along: they are keyed by
            # module name and the source's mtime, which copytree keeps, so the copy does not
            # compile them again (a minute of CPU per copy on a 2-core machine)
            shutil.copytree(source, tmp_path / name, ignore=shutil.ignore_patterns("*.pyc"))
        else:
            shutil.copy(source, tmp_path / name)
    # the objects as a newcomer lists them: a folder of meshes, through `objects --write`
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    for name in TINY_OBJECTS:
        load_source(f"primitive:{name}")[1].export(meshes / f"{name}.obj")
    params = yaml.safe_load((REPO / "params.yaml").read_text())
    params["objects"] = {}
    params["scales"] = list(TINY_SCALES)
    params["candidates"]["hands"] = list(TINY_HANDS)
    params["sample"]["count"] = 2000
    params["simulate"].update(spheres_per_object=5, workers=1)
    params["checks"].update(trials=4, robust_samples=2)
    params["report"].update(example_grasps=1)
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    listed = run([sys.executable, "-m", "pipeline", "objects", "meshes", "--write", "params.yaml"], tmp_path)
    assert listed.returncode == 0, listed.stderr
    params = yaml.safe_load((tmp_path / "params.yaml").read_text())
    assert params["objects"] == {
        name: {"source": str((meshes / f"{name}.obj").resolve()), "scale": 1.0} for name in TINY_OBJECTS
    }
    assert params["report"]["figure_objects"] == list(TINY_OBJECTS)  # the repository's mug, kettle... are gone
    (tmp_path / ".gitignore").write_text("__pycache__/\n")
    assert run(["git", "init", "-q"], tmp_path).returncode == 0
    assert run([sys.executable, "-m", "dvc", "init", "-q"], tmp_path).returncode == 0
    return params


def run_name(address):
    """``simulate@box-1.0-armar3`` of ``dag/simulate/box/dvc.yaml:simulate@1.0-armar3``,
    ``decompose@box`` of an object's one run (``code``, ``report`` of the stages' own files)."""
    path, name = address.split(":")
    parts = path.split("/")
    if len(parts) != 4:
        return name
    return f"{parts[1]}@{parts[2]}" + (f"-{name.split('@')[1]}" if "@" in name else "")


def ran_stages(result):
    """Names (``simulate@box-1.0-armar3``) of the stages a dvc command (or pipeline.repro's lanes,
    whose lines start with ``[object]``) ran."""
    lines = [line.split("] ", 1)[-1] if line.startswith("[") else line for line in result.stdout.splitlines()]
    return {run_name(line.split("'")[1]) for line in lines if line.startswith("Running stage")}


@pytest.mark.slow
def test_dvc_repro_report_on_a_tiny_config_caches_sweeps_and_restores(tmp_path):
    tiny_project(tmp_path)
    dvc = [sys.executable, "-m", "dvc"]
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    first = run([sys.executable, "-m", "pipeline.repro", "--jobs", "2"], tmp_path)  # what make run does
    assert first.returncode == 0, first.stderr + first.stdout
    runs, per_scale = TINY_RUNS, len(TINY_OBJECTS) * len(TINY_SCALES)
    # (the code stages' fingerprints came with the copy: the code has not changed)
    # decompose runs once per object (its parts serve both scales)
    assert len(ran_stages(first) - {"code"}) == per_scale * 6 + len(TINY_OBJECTS) + len(runs) * 3 + 1
    assert {f"decompose@{name}" for name in TINY_OBJECTS} <= ran_stages(first)

    # the report: a row per object x scale x hand, every trial, metrics, plots, figures
    out = tmp_path / "report"
    text = (out / "report.md").read_text()
    for name, scale, hand in runs:
        assert sum(line.startswith(f"| {name} | {scale:g} | {hand} |") for line in text.splitlines()) == 1
    assert "| capsule |" in text.split("## Table I")[1].split("##")[0]
    trials = pd.read_parquet(out / "trials.parquet")
    per_run = {
        run_key: pd.read_parquet(tmp_path / "data" / run_key[0] / str(run_key[1]) / run_key[2] / "trials.parquet")
        for run_key in runs
    }
    assert len(trials) == sum(len(frame) for frame in per_run.values())
    for (name, scale, hand), frame in per_run.items():
        mat = frame[frame.planner == "mat"]
        assert mat.sphere_index.nunique() <= 20 and (frame.planner == "baseline").sum() == len(mat)
        rows = trials[(trials.object == name) & (trials.scale == scale) & (trials.hand == hand)]
        assert rows.outcome.astype(str).tolist() == frame.outcome.astype(str).tolist()
    metrics = json.loads(run(dvc + ["metrics", "show", "--json"], tmp_path).stdout)
    shown = next(iter(metrics.values()))["data"]["report/metrics.json"]["data"]
    mat = trials[trials.planner == "mat"]
    # rounded to 4 decimals (a tie may go either way)
    assert shown["mat"]["force_closure_rate"] == pytest.approx((mat.outcome == "force_closure").mean(), abs=5.1e-5)
    assert set(shown["per_hand"]) == set(TINY_HANDS) and shown["runs_compared"] <= len(runs)
    plots = json.loads(run(dvc + ["plots", "show", "--json"], tmp_path).stdout)
    assert not plots.get("errors") and {"force_closure_pct", "epsilon_histogram"} <= set(plots["data"])
    bars = plots["data"]["force_closure_pct"][0]["content"]["data"]["values"]
    assert len(bars) == 2 * len(runs) and {bar["filename"] for bar in bars} == {
        "force_closure_mat.csv",
        "force_closure_baseline.csv",
    }
    assert (out / "figures" / "capsule-1.0-spheres.png").stat().st_size > 10_000
    timings = pd.read_json(tmp_path / "data" / "capsule" / "0.5" / "armar3" / "timing" / "simulate.json", typ="series")
    assert timings["stage"] == "simulate" and timings["process_seconds"] > timings["seconds"] > 0
    assert f"| simulate | {len(runs)} |" in text

    # every stage run wrote its MCAP log; classify, concavity and simulate their recordings, read back here
    logs = tmp_path / "logs"
    assert len(list(logs.rglob("*.mcap"))) == len(ran_stages(first) - {"code"}) and len(
        list(logs.rglob("*.rrd"))
    ) == 2 * per_scale + len(runs)
    folder = tmp_path / "data" / "capsule" / "1.0"
    spheres, symmetry = MedialSpheres.load(folder / "spheres.npz"), Symmetry.load(folder / "symmetry.npz")
    objects = logs / "capsule" / "1.0" / "object.rrd"
    assert instances(objects, "/capsule-1.0/spheres", "Ellipsoids3D:centers") == len(spheres)
    assert instances(objects, "/capsule-1.0/reduced", "Points3D:positions") == len(symmetry)
    for hand in ("armar3", "barrett"):
        candidates = pd.read_parquet(folder / hand / "candidates.parquet")
        trials_run = pd.read_parquet(folder / hand / "trials.parquet")
        grasps = logs / "capsule" / "1.0" / hand / "grasps.rrd"
        assert instances(grasps, f"/capsule-1.0/candidates/{hand}/approach", "Arrows3D:vectors") == len(candidates) > 0
        steps = rows_of(grasps, f"/capsule-1.0/outcome/{hand}").column("trial").to_pylist()
        assert sorted(steps) == list(range(len(trials_run)))
        messages = read_log(logs / "capsule" / "1.0" / hand / "simulate.mcap")
        topics = [topic for topic, _ in messages]
        assert topics.count("/trials") == len(trials_run) and topics.count("/stage") == 2
        assert topics.count("/artefacts") == 4 and topics.count("/counts") == topics.count("/timing") == 1
        hashed = {message["path"]: message["sha256"] for topic, message in messages if topic == "/artefacts"}
        assert hashed[f"data/capsule/1.0/{hand}/trials.parquet"] == file_digest(folder / hand / "trials.parquet")[0]
        logged = [message for topic, message in messages if topic == "/trials"]
        for row in (int(trials_run.epsilon.idxmax()), len(trials_run) - 1):
            assert [logged[row][key] for key in ("planner", "outcome", "sphere_index")] == [
                trials_run[key][row] for key in ("planner", "outcome", "sphere_index")
            ]
            assert logged[row]["epsilon"] == pytest.approx(trials_run.epsilon[row])
            assert logged[row]["joints"] == pytest.approx(list(trials_run.joints[row]))

    # nothing changed: nothing runs
    second = run(dvc + ["repro"], tmp_path)
    assert second.returncode == 0 and not ran_stages(second)

    # every stage ran only code among its deps (its log names the pipeline modules loaded)
    for path in logs.rglob("*.mcap"):
        loaded = dict(read_log(path))["/modules"]["modules"]
        files = {dag.module_path(name) for name in loaded}
        assert "pipeline/params.py" in files and files <= set(dag.code_deps(path.stem)), (path, files)

    # editing a module makes DVC rerun exactly the stages that import it: the code stages that
    # list it first, then, through their new fingerprints, the matrix entries
    quality = tmp_path / "pipeline" / "trial" / "quality.py"
    original = quality.read_text()
    quality.write_text(original + "\n# edited\n")
    code_stages = {
        f"dag/{entry.name}/dvc.yaml:code"
        for entry in dag.STAGES
        if "pipeline/trial/quality.py" in dag.code_deps(entry.name)
    }
    assert set(json.loads(run(dvc + ["status", "--json"], tmp_path).stdout)) == code_stages | {
        "dag/report/dvc.yaml:report"
    }

    def refresh_fingerprints():
        for key in code_stages:
            assert run(dvc + ["repro", "-s", key], tmp_path).returncode == 0

    refresh_fingerprints()
    status = run(dvc + ["status", "--json"], tmp_path)
    stale = {run_name(key) for key in json.loads(status.stdout)}
    quality.write_text(original)
    refresh_fingerprints()
    items = {
        entry.name: [
            f"{name}-{scale}" + (f"-{hand}" if entry.per_hand else "") if entry.per_scale else name
            for name in TINY_OBJECTS
            for scale in (TINY_SCALES if entry.per_scale else TINY_SCALES[:1])
            for hand in (TINY_HANDS if entry.per_hand else ("",))
        ]
        for entry in dag.STAGES
    }
    expected = {
        f"{entry.name}@{item}"
        for entry in dag.STAGES
        if "pipeline/trial/quality.py" in dag.code_deps(entry.name)
        for item in items[entry.name]
    } | {"report"}
    assert {"simulate@capsule-1.0-armar3", "check@capsule-0.5-armar3"} <= stale == expected
    # no geometry stage reruns when the trial's quality changes
    geometry = ("sample@", "medial_axis@", "mat@", "sphere_grid@", "classify@", "concavity@", "candidates@")
    assert not any(key.startswith(geometry) for key in stale)
    assert not json.loads(run(dvc + ["status", "--json"], tmp_path).stdout)

    # a parameter sweep with dvc exp: only what the parameter feeds reruns
    assert run(git + ["add", "-A"], tmp_path).returncode == 0
    assert run(git + ["commit", "-qm", "run"], tmp_path).returncode == 0
    before = {
        key: (tmp_path / "data" / key[0] / str(key[1]) / key[2] / "candidates.parquet").read_bytes() for key in runs
    }
    swept = run(dvc + ["exp", "run", "-S", "classify.min_object_angle_deg=150"], tmp_path)
    assert swept.returncode == 0, swept.stderr + swept.stdout
    ran = ran_stages(swept)
    # (concavity classifies the filled object, so it reads the classify params too)
    allowed = {"classify", "concavity", "candidates", "simulate", "check", "report"}
    assert {stage.split("@")[0] for stage in ran} <= allowed
    assert {
        f"{stage}@{name}-{scale}"
        for stage in ("classify", "concavity")
        for name in TINY_OBJECTS
        for scale in TINY_SCALES
    } <= ran
    for key in runs:  # trials rerun only where the candidates changed
        changed = (tmp_path / "data" / key[0] / str(key[1]) / key[2] / "candidates.parquet").read_bytes() != before[key]
        assert (f"simulate@{key[0]}-{key[1]}-{key[2]}" in ran) == changed
    shown = json.loads(run(dvc + ["exp", "show", "--json"], tmp_path).stdout)
    assert "150" in json.dumps(shown)

    # the checks off: DVC would rerun only the check stages (then the report, which reads their
    # tables); every other artefact keeps its deps (a table of no checks: test_grasp_checks)
    params_file = tmp_path / "params.yaml"
    kept = params_file.read_text()
    edited = yaml.safe_load(kept)
    edited["checks"]["trials"] = 0
    params_file.write_text(yaml.safe_dump(edited))
    stale = {run_name(key) for key in json.loads(run(dvc + ["status", "--json"], tmp_path).stdout)}
    assert stale == {f"check@{name}-{scale}-{hand}" for name, scale, hand in runs}
    params_file.write_text(kept)

    # push to a local remote, then a fresh clone pulls back every artefact, byte for byte
    assert run(git + ["checkout", "--", "."], tmp_path).returncode == 0
    assert run(dvc + ["checkout", "-q"], tmp_path).returncode == 0
    assert run(dvc + ["remote", "add", "-d", "store", str(tmp_path.parent / "store")], tmp_path).returncode == 0
    assert run(git + ["commit", "-qam", "remote"], tmp_path).returncode == 0
    pushed = run(dvc + ["push"], tmp_path)
    assert pushed.returncode == 0, pushed.stderr
    clone = tmp_path.parent / "clone"
    assert run(["git", "clone", "-q", str(tmp_path), str(clone)], tmp_path.parent).returncode == 0
    pulled = run(dvc + ["pull"], clone)
    assert pulled.returncode == 0, pulled.stderr
    outputs = sorted(
        path.relative_to(tmp_path)
        for folder in ("data", "report", "logs")
        for path in (tmp_path / folder).rglob("*")
        if path.is_file() and path.name[0] != "."
    )
    assert (
        len(outputs)
        == per_scale * 10
        + len(runs) * 5
        + 6
        + len(list((out / "figures").iterdir()))
        + per_scale * 6
        + len(runs) * 3
        + 1
        + len(TINY_OBJECTS) * 3  # decompose: parts, timing, log
        + per_scale * 4  # concavity: concavities, timing, log, recording
        + len(runs) * 3  # check: checks, timing, log
        + 2  # the calibration plots
    )
    for relative in outputs:
        assert (clone / relative).read_bytes() == (tmp_path / relative).read_bytes()


@pytest.mark.slow
def test_hands_cli_exports_a_hand_that_plan_accepts_and_renders_pictures(tmp_path):
    exported = run([sys.executable, "-m", "pipeline", "hands", "--export", "parallel_jaw", "myhand"], tmp_path)
    assert exported.returncode == 0, exported.stderr
    assert {path.name for path in (tmp_path / "myhand").iterdir()} == {"parallel_jaw.urdf", "parallel_jaw.yaml"}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(complete_params({"sample": {"count": 3000}})))
    planned = run(
        [
            sys.executable,
            "-m",
            "pipeline",
            "plan",
            "primitive:box",
            "--hand",
            "myhand/parallel_jaw.yaml",
            "--params",
            "params.yaml",
            "--spheres",
            "2",
            "--baseline",
            "3",
            "--workers",
            "1",
            "--out",
            "out",
        ],
        tmp_path,
    )
    assert planned.returncode == 0, planned.stderr
    trials = pd.read_parquet(tmp_path / "out" / "trials.parquet")
    assert set(trials.hand) == {"parallel_jaw"} and (trials.planner == "baseline").sum() == 3
    rendered = run([sys.executable, "-m", "pipeline", "hands", "--render", "pictures"], tmp_path)
    assert rendered.returncode == 0, rendered.stderr
    assert {path.name for path in (tmp_path / "pictures").iterdir()} == {
        "armar3.png",
        "barrett.png",
        "parallel_jaw.png",
        "franka.png",
    }
    bad = run(
        [sys.executable, "-m", "pipeline", "plan", "primitive:box", "--hand", "nohand.yaml", "--out", "x"], tmp_path
    )
    assert bad.returncode == 2 and bad.stderr == "error: nohand.yaml: hand spec not found\n"


@pytest.mark.slow
def test_plan_batch_and_dvc_make_the_same_artefacts(tmp_path):
    """The three entry points on one mesh, params and seed: the same bytes, the checks too (batch
    keeps only the trials, with an ``object`` column in front and the checks on their rows)."""
    import trimesh

    meshes = tmp_path / "meshes"
    meshes.mkdir()
    trimesh.creation.box([0.06, 0.04, 0.03]).export(meshes / "block.obj")
    project = tmp_path / "project"
    project.mkdir()
    params = tiny_project(project)
    params.update(objects={"block": {"source": str(meshes / "block.obj")}}, scales=[1.0], seed=4)
    params["candidates"]["hands"] = ["barrett"]
    params["simulate"].update(spheres_per_object=3, baseline_trials=3)
    params["report"]["figure_objects"] = ["block"]
    (project / "params.yaml").write_text(yaml.safe_dump(params))
    assert run([sys.executable, "-m", "pipeline.dag"], project).returncode == 0  # the new object's stage files
    repro = run([sys.executable, "-m", "dvc", "repro"], project)
    assert repro.returncode == 0, repro.stderr + repro.stdout
    planned = run(
        [
            sys.executable,
            "-m",
            "pipeline",
            "plan",
            str(meshes / "block.obj"),
            "--params",
            str(project / "params.yaml"),
            "--out",
            str(tmp_path / "plan"),
        ],
        REPO,
    )
    assert planned.returncode == 0, planned.stderr
    batch = run(
        [
            sys.executable,
            "-m",
            "pipeline",
            "batch",
            str(meshes),
            "--hand",
            "barrett",
            "--params",
            str(project / "params.yaml"),
            "--workers",
            "1",
            "--out",
            str(tmp_path / "batch"),
        ],
        REPO,
    )
    assert batch.returncode == 0, batch.stderr

    run_folder = project / "data" / "block" / "1.0"
    for stage in dag.STAGES:
        for artefact in stage.outputs:
            name = dag.ARTEFACTS[artefact]
            dvc_path = run_folder / "barrett" / name if artefact in dag.PER_HAND else run_folder / name
            if artefact in dag.PER_OBJECT:  # the object's parts, of its first scale (1.0 here)
                dvc_path = run_folder.parent / name
            assert (tmp_path / "plan" / name).read_bytes() == dvc_path.read_bytes(), name
    trials = pd.read_parquet(tmp_path / "plan" / "trials.parquet")
    assert len(trials) > 3 and (trials.planner == "baseline").sum() == 3
    from_batch = pd.read_parquet(tmp_path / "batch" / "trials" / "block.parquet")
    assert from_batch.object.unique().tolist() == ["block"]
    checks = pd.read_parquet(tmp_path / "plan" / "checks.parquet")  # batch puts them on the trials
    pd.testing.assert_frame_equal(from_batch.drop(columns="object"), with_checks(trials, checks))

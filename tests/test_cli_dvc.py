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

REPO = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(REPO), "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}


def run(args, cwd):
    return subprocess.run(args, cwd=cwd, capture_output=True, text=True, env=ENV)


@pytest.mark.slow
def test_plan_writes_every_artefact_and_summary(tmp_path):
    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"sample": {"count": 3000}}))
    plan = [sys.executable, "-m", "pipeline", "plan", "primitive:box", "--seed", "3", "--params", "params.yaml",
            "--spheres", "3", "--baseline", "4", "--workers", "1"]
    result = run(plan + ["--out", "out"], tmp_path)
    assert result.returncode == 0, result.stderr
    names = {path.name for path in (tmp_path / "out").iterdir()}
    assert names == {"surface.npz", "medial_axis.npz", "spheres.npz", "sphere_grid.npz", "symmetry.npz",
                     "candidates.parquet", "trials.parquet", "contacts.parquet", "summary.json"}
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["counts"]["surface_samples"] == 3000 and summary["seed"] == 3
    assert set(summary["timings_s"]) == {"sample", "medial_axis", "mat", "sphere_grid", "classify", "candidates",
                                         "simulate"}
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
    # the same seed gives the same artefacts
    again = run(plan + ["--out", "again"], tmp_path)
    assert again.returncode == 0
    for name in ("surface.npz", "spheres.npz", "sphere_grid.npz", "symmetry.npz", "candidates.parquet",
                 "trials.parquet", "contacts.parquet"):
        assert (tmp_path / "out" / name).read_bytes() == (tmp_path / "again" / name).read_bytes()


@pytest.mark.slow
def test_plan_on_bad_mesh_is_one_line(tmp_path):
    (tmp_path / "broken.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    result = run([sys.executable, "-m", "pipeline", "plan", "broken.obj", "--out", "out"], tmp_path)
    assert result.returncode == 2 and result.stderr.startswith("error: broken.obj")
    assert result.stderr.count("\n") == 1 and not (tmp_path / "out").exists()
    unknown = run([sys.executable, "-m", "pipeline", "plan", "primitive:box", "--hand", "shadow", "--out", "out"],
                  tmp_path)
    assert unknown.returncode == 2 and unknown.stderr == \
        "error: unknown hand 'shadow' (built-in: armar3, barrett, parallel_jaw; or a spec .yaml/.toml)\n"
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_dvc_repro_caches_and_reruns_only_what_changed(tmp_path):
    for name in ("pipeline", "stages", "dvc.yaml"):
        source = REPO / name
        if source.is_dir():
            shutil.copytree(source, tmp_path / name, ignore=shutil.ignore_patterns("__pycache__"))
        else:
            shutil.copy(source, tmp_path / name)
    params = yaml.safe_load((REPO / "params.yaml").read_text())
    params["objects"] = {"box": params["objects"]["box"], "capsule": params["objects"]["capsule"]}
    params["sample"]["count"] = 2000
    params["simulate"].update(spheres_per_object=2, baseline_trials=3, workers=1)
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    dvc = [sys.executable, "-m", "dvc"]
    assert run(["git", "init", "-q"], tmp_path).returncode == 0
    assert run(dvc + ["init", "-q"], tmp_path).returncode == 0
    first = run(dvc + ["repro"], tmp_path)
    assert first.returncode == 0, first.stderr + first.stdout
    assert (tmp_path / "data" / "capsule" / "sphere_grid.npz").exists()
    second = run(dvc + ["repro"], tmp_path)
    assert second.returncode == 0 and "Running stage" not in second.stdout
    before = {name: (tmp_path / "data" / name / "candidates.parquet").read_bytes() for name in ("box", "capsule")}
    params["mat"]["tau"] = 0.02
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    third = run(dvc + ["repro"], tmp_path)
    assert third.returncode == 0, third.stderr
    ran = {line.split("'")[1] for line in third.stdout.splitlines() if line.startswith("Running stage")}
    assert ran - {"simulate@box", "simulate@capsule"} == {
        f"{stage}@{name}" for stage in ("mat", "sphere_grid", "classify", "candidates") for name in ("box", "capsule")}
    for name in ("box", "capsule"):  # trials rerun only where the candidates changed
        changed = (tmp_path / "data" / name / "candidates.parquet").read_bytes() != before[name]
        assert (f"simulate@{name}" in ran) == changed
    assert (tmp_path / "data" / "box" / "trials.parquet").exists()

    # push to a local remote, then a fresh clone pulls back every artefact, byte for byte
    assert run(dvc + ["remote", "add", "-d", "store", str(tmp_path.parent / "store")], tmp_path).returncode == 0
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    assert run(git + ["add", "-A"], tmp_path).returncode == 0
    assert run(git + ["commit", "-qm", "run"], tmp_path).returncode == 0
    pushed = run(dvc + ["push"], tmp_path)
    assert pushed.returncode == 0, pushed.stderr
    clone = tmp_path.parent / "clone"
    assert run(["git", "clone", "-q", str(tmp_path), str(clone)], tmp_path.parent).returncode == 0
    pulled = run(dvc + ["pull"], clone)
    assert pulled.returncode == 0, pulled.stderr
    outputs = sorted(path.relative_to(tmp_path) for path in (tmp_path / "data").rglob("*.*") if path.name[0] != ".")
    assert len(outputs) == 16
    for relative in outputs:
        assert (clone / relative).read_bytes() == (tmp_path / relative).read_bytes()


@pytest.mark.slow
def test_hands_cli_exports_a_hand_that_plan_accepts_and_renders_pictures(tmp_path):
    exported = run([sys.executable, "-m", "pipeline", "hands", "--export", "parallel_jaw", "myhand"], tmp_path)
    assert exported.returncode == 0, exported.stderr
    assert {path.name for path in (tmp_path / "myhand").iterdir()} == {"parallel_jaw.urdf", "parallel_jaw.yaml"}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"sample": {"count": 3000}}))
    planned = run([sys.executable, "-m", "pipeline", "plan", "primitive:box", "--hand", "myhand/parallel_jaw.yaml",
                   "--params", "params.yaml", "--spheres", "2", "--baseline", "3", "--workers", "1", "--out", "out"],
                  tmp_path)
    assert planned.returncode == 0, planned.stderr
    trials = pd.read_parquet(tmp_path / "out" / "trials.parquet")
    assert set(trials.hand) == {"parallel_jaw"} and (trials.planner == "baseline").sum() == 3
    rendered = run([sys.executable, "-m", "pipeline", "hands", "--render", "pictures"], tmp_path)
    assert rendered.returncode == 0, rendered.stderr
    assert {path.name for path in (tmp_path / "pictures").iterdir()} == {"armar3.png", "barrett.png",
                                                                         "parallel_jaw.png"}
    bad = run([sys.executable, "-m", "pipeline", "plan", "primitive:box", "--hand", "nohand.yaml", "--out", "x"],
              tmp_path)
    assert bad.returncode == 2 and bad.stderr == "error: nohand.yaml: hand spec not found\n"

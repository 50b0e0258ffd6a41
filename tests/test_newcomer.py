"""What a newcomer hits (issue 14): objects validates and recurses, --write keeps figure_objects
valid, plan warns, --help documents, batch subsets, the units error names --scale, and the
installed medial-grasp command works from any folder."""

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
import yaml
from dvc.stage.utils import is_valid_name

from conftest import complete_params
from pipeline.__main__ import main
from pipeline.batch import find_meshes
from pipeline.errors import BadInputError, BadParamsError
from pipeline.geometry.catalogue import figure_objects_following
from pipeline.geometry.objects import check_size, object_name, select_meshes
from pipeline.hands.spec import HANDS

REPO = Path(__file__).resolve().parents[1]


def open_tube(wave=0.0):
    """A 4 cm x 10 cm tube without its end caps; ``wave`` (m) bends the top rim out of its plane."""
    tube = trimesh.creation.cylinder(radius=0.02, height=0.1, sections=64)
    vertices = tube.vertices.copy()
    top = vertices[:, 2] > 0
    vertices[top, 2] += wave * np.cos(3 * np.arctan2(vertices[top, 1], vertices[top, 0]))
    return trimesh.Trimesh(vertices, tube.faces[np.abs(tube.face_normals[:, 2]) < 0.5])


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A nested folder: a good box and mug, a tube with planar open ends (capped), a tube with a
    wavy open end (refused) and a box in millimetres (refused); cwd holds no params.yaml."""
    meshes = tmp_path / "meshes"
    (meshes / "sub dir" / "deeper").mkdir(parents=True)
    trimesh.creation.box(extents=[0.1, 0.06, 0.02]).export(meshes / "box.obj")
    trimesh.creation.box(extents=[0.08, 0.08, 0.1]).export(meshes / "mug.stl")
    open_tube().export(meshes / "sub dir" / "deeper" / "tube.obj")
    open_tube(wave=0.004).export(meshes / "sub dir" / "bowl.obj")
    trimesh.creation.box(extents=[100, 60, 20]).export(meshes / "sub dir" / "mm_box.stl")
    monkeypatch.chdir(tmp_path)
    return meshes


def warnings_of(stderr):
    return [line for line in stderr.splitlines() if line.startswith("warning: ")]


def test_objects_validates_recursively_and_skips_bad_meshes_with_one_warning_each(folder, capsys):
    main(["objects", str(folder)])
    out, err = capsys.readouterr()
    entries = yaml.safe_load(out)["objects"]
    assert list(entries) == ["box", "mug", "sub_dir-deeper-tube"]  # natural order of the stems
    assert entries["sub_dir-deeper-tube"] == {"source": str(folder / "sub dir" / "deeper" / "tube.obj"), "scale": 1.0}
    assert all(is_valid_name(name) and re.fullmatch(r"[A-Za-z][A-Za-z0-9_-]*", name) for name in entries)
    skipped = [line for line in warnings_of(err) if line.startswith("warning: skipped ")]
    assert len(skipped) == 2 and len(err.splitlines()) == 3  # 2 skipped, 1 capped; nothing else
    bowl, mm_box = sorted(skipped)
    assert "bowl.obj: surface is not closed" in bowl
    assert "mm_box.stl: bounding-box diagonal" in mm_box and "--scale 0.001" in mm_box
    assert any("tube.obj: open surface closed by capping" in line for line in warnings_of(err))
    # the millimetre box passes once scaled, and --only keeps stems anywhere in the tree
    main(["objects", str(folder), "--scale", "0.001", "--only", "mm_box"])
    assert list(yaml.safe_load(capsys.readouterr().out)["objects"]) == ["sub_dir-mm_box"]


def test_objects_checks_every_params_scale_and_refuses_a_name_clash(folder, capsys):
    params = complete_params({"scales": [1.0, 0.01]})  # 0.01 makes the 12 cm box 1.2 mm: below min_extent
    (folder.parent / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(SystemExit) as exited:  # nothing passes at every scale: an error, not an empty section
        main(["objects", str(folder), "--only", "box"])
    lines = capsys.readouterr().err.splitlines()
    assert exited.value.code == 2 and len(lines) == 2
    assert "box.obj: bounding-box diagonal" in lines[0] and lines[0].endswith("[at params scale 0.01]")
    assert lines[1].startswith("error: ") and "no mesh passed" in lines[1]
    (folder.parent / "params.yaml").unlink()
    trimesh.creation.box(extents=[0.1, 0.1, 0.1]).export(folder / "box.stl")
    with pytest.raises(SystemExit) as exited:
        main(["objects", str(folder)])
    lines = capsys.readouterr().err.splitlines()
    assert exited.value.code == 2 and len(lines) == 1 and "both give the object name 'box'" in lines[0]


def test_object_names_are_dvc_names_that_yaml_reads_back():
    assert object_name(Path("sub dir/2.obj")) == "sub_dir-2"
    assert object_name(Path("a-b.obj")) == "a_b"  # '-' only ever separates folders
    assert object_name(Path("7.off")) == "mesh_7" and object_name(Path("true.obj")) == "mesh_true"
    assert object_name(Path("x/y.ply"), prefix="chen_") == "chen_x-y"


def test_objects_write_keeps_figure_objects_naming_objects(folder, capsys):
    from pipeline.params import load_params

    params = folder.parent / "params.yaml"
    shutil.copy(REPO / "params.yaml", params)
    main(["objects", str(folder), "--write", str(params)])
    written = yaml.safe_load(params.read_text())
    assert list(written["objects"]) == ["box", "mug", "sub_dir-deeper-tube"]  # the bad meshes left out
    assert written["report"]["figure_objects"] == ["mug"]  # the one still present (kettle, giraffe gone)
    assert "# drawn as figures" in params.read_text()
    loaded = load_params(params)  # the whole file still loads, figure_objects included
    assert set(loaded.report.figure_objects) <= set(loaded.objects)
    (folder / "mug.stl").unlink()
    main(["objects", str(folder), "--write", str(params)])
    written = yaml.safe_load(params.read_text())
    assert written["report"]["figure_objects"] == ["box", "sub_dir-deeper-tube"]  # none left: the first (up to 3)
    assert set(written["report"]["figure_objects"]) <= set(written["objects"])
    assert "report.figure_objects: box, sub_dir-deeper-tube" in capsys.readouterr().out


def test_figure_objects_rewrite_handles_block_lists_and_a_missing_key():
    block = "objects:\n  a: {}\nreport:\n  figure_objects:   # drawn\n    - gone\n    - a\n  epsilon_bins: 20\n"
    text, figures = figure_objects_following(block, ["a", "b"], source="p.yaml")
    assert figures == ["a"] and yaml.safe_load(text)["report"] == {"figure_objects": ["a"], "epsilon_bins": 20}
    assert "# drawn" in text
    text, figures = figure_objects_following("objects:\n  b: {}\n", ["b"], source="p.yaml")
    assert figures == ["b"] and yaml.safe_load(text)["report"] == {"figure_objects": ["b"]}
    text, _ = figure_objects_following("objects: {}\nreport:\n  epsilon_bins: 20\n", ["yes"], source="p.yaml")
    assert yaml.safe_load(text)["report"] == {"figure_objects": ["yes"], "epsilon_bins": 20}  # quoted, not True


def plan(tmp_path, mesh, *extra):
    """In-process ``plan --no-simulate`` on 3000 samples: the summary dict."""
    params = tmp_path / "tiny.yaml"
    params.write_text(yaml.safe_dump(complete_params({"sample": {"count": 3000}})))
    out = tmp_path / f"out{len(list(tmp_path.glob('out*')))}"
    main(["plan", mesh, "--no-simulate", "--params", str(params), "--out", str(out), *extra])
    return json.loads((out / "summary.json").read_text())


def test_plan_warns_when_a_hand_gets_no_candidates_and_lists_it_with_zero(tmp_path, capsys):
    # a 20 cm ball: every medial sphere is wider than armar3 (9.4 cm) and barrett (14 cm) can hold
    summary = plan(tmp_path, "primitive:sphere", "--scale", "2.5")
    assert summary["candidates"] == {"armar3": 0, "barrett": 0}
    assert len(summary["warnings"]) == 2
    assert all("no grasp candidates" in line and "max_graspable_diameter" in line for line in summary["warnings"])
    assert warnings_of(capsys.readouterr().err) == [f"warning: {line}" for line in summary["warnings"]]
    # one of two hands empty: both listed, one warning
    summary = plan(tmp_path, "primitive:sphere", "--scale", "1.5", "--hand", "armar3", "--hand", "barrett")
    assert summary["candidates"]["armar3"] == 0 < summary["candidates"]["barrett"]
    assert len(summary["warnings"]) == 1 and summary["warnings"][0].startswith("hand armar3:")


def test_plan_warns_about_a_capped_hole_and_lists_no_warning_when_there_is_none(tmp_path, capsys):
    open_tube().export(tmp_path / "tube.obj")
    summary = plan(tmp_path, str(tmp_path / "tube.obj"))
    assert len(summary["warnings"]) == 1 and "tube.obj: open surface closed by capping" in summary["warnings"][0]
    assert summary["candidates"]["armar3"] > 0
    assert warnings_of(capsys.readouterr().err) == [f"warning: {summary['warnings'][0]}"]
    assert plan(tmp_path, "primitive:box")["warnings"] == []
    assert warnings_of(capsys.readouterr().err) == []


def help_of(command, capsys):
    with pytest.raises(SystemExit) as exited:
        main([command, "--help"])
    assert exited.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", ["plan", "batch", "bench", "hands", "objects"])
def test_every_subcommand_help_has_a_description_and_an_example(command, capsys):
    text = help_of(command, capsys)
    example = text.split("example:\n", 1)[1].splitlines()[0].strip()
    assert example.startswith(f"python -m pipeline {command} ")
    description = text.split("\n\n")[1]
    assert len(description) > 40 and not description.startswith(("positional", "options"))


def test_help_states_real_defaults_and_lists_the_built_in_hands(capsys):
    plan_help = " ".join(help_of("plan", capsys).split())  # argparse wraps lines
    assert "default: params simulate.spheres_per_object" in plan_help and "(default: params, 200)" not in plan_help
    hands_help = help_of("hands", capsys)
    assert all(name in hands_help for name in HANDS)


def test_batch_only_and_limit_select_a_subset(tmp_path):
    for relative in ("b/2.obj", "b/10.obj", "a/1.obj", "3.stl"):
        (tmp_path / relative).parent.mkdir(exist_ok=True)
        (tmp_path / relative).write_text("")
    meshes = find_meshes(tmp_path)
    assert [name for name, _ in meshes] == ["1", "2", "3", "10"]
    assert [name for name, _ in select_meshes(meshes, folder=tmp_path, only=["10", "1"])] == ["1", "10"]
    assert [name for name, _ in select_meshes(meshes, folder=tmp_path, limit=2)] == ["1", "2"]
    assert [name for name, _ in select_meshes(meshes, folder=tmp_path, only=["3", "10", "2"], limit=2)] == ["2", "3"]
    assert select_meshes(meshes, folder=tmp_path, limit=10) == meshes
    with pytest.raises(BadInputError, match="no mesh named 4, 7"):
        select_meshes(meshes, folder=tmp_path, only=["7", "1", "4"])
    with pytest.raises(BadParamsError, match="--limit must be at least 1"):
        select_meshes(meshes, folder=tmp_path, limit=0)


def test_batch_cli_refuses_an_unknown_stem_before_ray_starts(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "meshes").mkdir()
    trimesh.creation.box(extents=[0.1, 0.06, 0.02]).export(tmp_path / "meshes" / "box.obj")
    with pytest.raises(SystemExit) as exited:
        main(["batch", "meshes", "--hand", "barrett", "--out", "out", "--only", "box,nosuch"])
    assert exited.value.code == 2 and capsys.readouterr().err == "error: meshes: no mesh named nosuch\n"
    assert not (tmp_path / "out").exists()


def test_units_error_names_the_command_line_fix_in_one_line():
    with pytest.raises(BadInputError) as raised:
        check_size(np.array([[0, 0, 0], [100, 60, 20]]), name="part.stl", min_extent=0.005, max_extent=5.0)
    message = str(raised.value)
    assert message.startswith("part.stl: bounding-box diagonal 118.3 m") and "\n" not in message
    assert (
        "wrong units? (for a mesh in millimetres pass --scale 0.001, or set the object's scale in params.yaml)"
        in message
    )


def test_medial_grasp_command_works_outside_the_repository(tmp_path):
    script = Path(sys.executable).parent / "medial-grasp"
    assert script.is_file(), "no medial-grasp in the venv: run `make setup`"
    env = {key: value for key, value in os.environ.items() if key != "PYTHONPATH"}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(complete_params({"sample": {"count": 3000}})))
    shown = subprocess.run([str(script), "objects", "--help"], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert shown.returncode == 0 and "medial-grasp objects " in shown.stdout  # the examples name the command
    planned = subprocess.run(
        [str(script), "plan", "primitive:box", "--no-simulate", "--out", "out"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env=env,
    )
    assert planned.returncode == 0, planned.stderr
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["counts"]["surface_samples"] == 3000  # this folder's params.yaml was read
    assert summary["candidates"]["armar3"] > 0 and summary["warnings"] == []
    assert REPO not in tmp_path.parents and tmp_path != REPO


def test_a_run_without_trials_has_no_rate_not_zero(tmp_path, capsys):
    # the 20 cm ball again, simulated: no candidates, so no trials; the rates are null in JSON
    # (NaN in Python and in batch's tables), never 0 %
    params = tmp_path / "tiny.yaml"
    params.write_text(yaml.safe_dump(complete_params({"sample": {"count": 3000}})))
    main(["plan", "primitive:sphere", "--scale", "2.5", "--params", str(params), "--out", str(tmp_path / "out")])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["trials"] == 0 and summary["force_closure_rate"] is None and summary["mean_epsilon"] is None
    assert summary["baseline"]["trials"] == 0 and summary["baseline"]["force_closure_rate"] is None

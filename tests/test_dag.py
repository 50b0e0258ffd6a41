"""The stage table (pipeline.dag): the committed DVC files are written from it, and each stage's
code deps are the modules it imports."""

import pytest

from pipeline import dag
from pipeline.errors import PipelineError
from pipeline.params import SECTIONS


def test_committed_dvc_files_are_written_from_the_table():
    # a stage that gains an import, or a table edit, leaves its dag/<stage>/dvc.yaml stale
    assert dag.write_dvc_files(check=True) == []


def test_import_walk_finds_every_form(tmp_path, monkeypatch):
    (tmp_path / "pipeline").mkdir()
    for name in ("alpha", "beta", "gamma", "delta", "epsilon"):
        (tmp_path / "pipeline" / f"{name}.py").write_text("")
    (tmp_path / "pipeline" / "alpha.py").write_text("from .beta import thing\n")
    stage = tmp_path / "stages" / "demo.py"
    stage.parent.mkdir()
    stage.write_text(
        "import os\nimport pipeline.gamma\nfrom pipeline import delta, not_a_module\n"
        "from pipeline.alpha import x\n\ndef main():\n    from pipeline.epsilon import y\n"
    )
    monkeypatch.setattr(dag, "ROOT", tmp_path)
    dag.code_deps.cache_clear()
    try:
        assert dag._imported(stage) == {"gamma", "delta", "alpha", "epsilon"}
        assert dag._imported(tmp_path / "pipeline" / "alpha.py") == {"beta"}
        assert dag.code_deps("demo") == (
            "stages/demo.py",
            "pipeline/__init__.py",
            "pipeline/alpha.py",
            "pipeline/beta.py",
            "pipeline/delta.py",
            "pipeline/epsilon.py",
            "pipeline/gamma.py",
        )
    finally:
        dag.code_deps.cache_clear()


def test_code_deps_follow_the_imports_and_stay_tight():
    simulate = set(dag.code_deps("simulate"))
    # the trial engine's modules reach simulate only through pipeline.trials -> simulation
    assert {
        "pipeline/trials.py",
        "pipeline/simulation.py",
        "pipeline/proximity.py",
        "pipeline/mesh_query.py",
        "pipeline/contacts.py",
        "pipeline/quality.py",
        "pipeline/kinematics.py",
        "pipeline/urdf.py",
        "pipeline/params.py",
        "pipeline/stage_io.py",
        "pipeline/artefacts.py",
    } <= simulate
    # the geometry stages do not rerun when the trial engine changes
    for name in ("sample", "medial_axis", "mat", "sphere_grid", "candidates"):
        assert not {"pipeline/simulation.py", "pipeline/quality.py", "pipeline/recording.py"} & set(dag.code_deps(name))
    assert "pipeline/medial_axis.py" in dag.code_deps("medial_axis")
    assert {"pipeline/mat.py", "pipeline/cell_grid.py"} <= set(dag.code_deps("mat"))
    assert "pipeline/figures.py" in dag.code_deps("report") and "pipeline/figures.py" not in simulate
    with pytest.raises(PipelineError, match="no stage named 'sampel'"):
        dag.stage("sampel")


def test_table_chains_every_input_to_an_earlier_output():
    made = set()
    for entry in dag.STAGES:
        assert set(entry.inputs) <= made, entry.name
        made |= set(entry.outputs)
    assert made == set(dag.ARTEFACTS)


def test_each_stage_module_calls_the_tables_function():
    import ast

    for entry in dag.STAGES:
        module, name = entry.function.split(":")
        tree = ast.parse((dag.ROOT / "stages" / f"{entry.name}.py").read_text())
        imported = {
            (node.module, alias.name)
            for node in ast.walk(tree)
            if isinstance(node, ast.ImportFrom)
            for alias in node.names
        }
        called = {
            node.func.id for node in ast.walk(tree) if isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
        }
        called_on = {
            (node.func.value.id, node.func.attr)
            for node in ast.walk(tree)
            if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name)
        }
        parent, leaf = module.rsplit(".", 1)
        direct = (module, name) in imported and name in called
        via_module = (parent, leaf) in imported and (leaf, name) in called_on
        assert direct or via_module, entry.name
        assert callable(dag.function(entry))
        assert not entry.section or entry.section in SECTIONS


def test_matrix_entries_take_their_code_deps_through_one_fingerprint(tmp_path):
    import hashlib
    import json

    import yaml

    for entry in dag.STAGES:
        code = yaml.safe_load(dag.dvc_file(entry.name))["stages"]["code"]
        assert code["deps"] == list(dag.code_deps(entry.name)) + ["pipeline/dag.py"]
        assert code["outs"] == [{dag.fingerprint_path(entry.name): {"cache": False}}]
        deps = yaml.safe_load(dag.object_dvc_file(entry.name, "duck"))["stages"][entry.name]["deps"]
        assert deps[0] == dag.fingerprint_path(entry.name) and not any(
            path.startswith(("pipeline/", "stages/")) for path in deps
        )
    # the fingerprint is each source file's md5, so an edit to any of them changes it
    out = tmp_path / "code.json"
    dag.main(["--fingerprint", "simulate", str(out)])
    written = json.loads(out.read_text())
    assert written["stage"] == "simulate" and list(written["files"]) == sorted(dag.code_deps("simulate"))
    quality = (dag.ROOT / "pipeline" / "quality.py").read_bytes()
    assert written["files"]["pipeline/quality.py"] == hashlib.md5(quality).hexdigest()


def test_each_object_has_its_own_stage_files_written_from_params(tmp_path):
    import yaml

    from pipeline.params import defaults

    params = defaults()
    params["objects"] = {"cube": {"source": "primitive:box"}, "ring": {"source": "primitive:torus"}}
    params["report"]["figure_objects"] = []
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    written = dag.write_dvc_files(tmp_path)
    per_object = {f"dag/{entry.name}/{name}/dvc.yaml" for entry in dag.STAGES for name in ("cube", "ring")}
    assert {str(path.relative_to(tmp_path)) for path in written} == per_object | {
        f"dag/{entry.name}/dvc.yaml" for entry in dag.STAGES + (dag.REPORT,)
    }
    assert dag.write_dvc_files(tmp_path, check=True) == []
    simulate = yaml.safe_load((tmp_path / "dag/simulate/ring/dvc.yaml").read_text())["stages"]["simulate"]
    assert simulate["matrix"] == {"scale": "${scales}", "hand": "${candidates.hands}"}
    assert simulate["deps"][1:] == [
        "data/ring/${item.scale}/surface.npz",
        "data/ring/${item.scale}/${item.hand}/candidates.parquet",
    ]
    sample = yaml.safe_load((tmp_path / "dag/sample/cube/dvc.yaml").read_text())["stages"]["sample"]
    assert (
        sample["params"] == ["seed", "sample", "objects.cube"] and "stages.sample cube ${item.scale}" in sample["cmd"]
    )
    # an object dropped from params.yaml: --check lists its files, the rewrite removes them with their locks
    (tmp_path / "dag/sample/ring/dvc.lock").write_text("schema: '2.0'\n")
    del params["objects"]["ring"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    ring = {tmp_path / f"dag/{entry.name}/ring/dvc.yaml" for entry in dag.STAGES}
    assert set(dag.write_dvc_files(tmp_path, check=True)) == ring and all(path.is_file() for path in ring)
    assert set(dag.write_dvc_files(tmp_path)) == ring
    assert not any((tmp_path / f"dag/{entry.name}/ring").exists() for entry in dag.STAGES)
    assert (tmp_path / "dag/sample/cube/dvc.yaml").is_file() and dag.write_dvc_files(tmp_path, check=True) == []

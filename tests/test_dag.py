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
    package = tmp_path / "pipeline"
    (package / "sub").mkdir(parents=True)
    for name in ("__init__", "alpha", "beta", "gamma", "delta", "epsilon", "zeta"):
        (package / f"{name}.py").write_text("")
    (package / "sub" / "__init__.py").write_text('"""a sub-package"""\n')
    (package / "sub" / "inner.py").write_text("from ..zeta import z\nfrom . import leaf\n")
    (package / "sub" / "leaf.py").write_text("")
    (package / "alpha.py").write_text("from .beta import thing\n")
    stage = tmp_path / "stages" / "demo.py"
    stage.parent.mkdir()
    stage.write_text(
        "import os\nimport pipeline.gamma\nfrom pipeline import delta, not_a_module\n"
        "from pipeline.alpha import x\nfrom pipeline.sub.inner import y\n\n"
        "def main():\n    from pipeline.epsilon import y\n"
    )
    monkeypatch.setattr(dag, "ROOT", tmp_path)
    dag.code_deps.cache_clear()
    try:
        assert dag._imported(stage) == {("gamma",), ("delta",), ("alpha",), ("epsilon",), ("sub", "inner")}
        assert dag._imported(package / "alpha.py") == {("beta",)}
        # relative imports climb out of a sub-package; `from . import leaf` names the module
        assert dag._imported(package / "sub" / "inner.py") == {("zeta",), ("sub",), ("sub", "leaf")}
        assert dag.code_deps("demo") == (
            "stages/demo.py",
            "pipeline/__init__.py",
            "pipeline/alpha.py",
            "pipeline/beta.py",
            "pipeline/delta.py",
            "pipeline/epsilon.py",
            "pipeline/gamma.py",
            "pipeline/sub/__init__.py",  # Python runs a sub-package's __init__ before its modules
            "pipeline/sub/inner.py",
            "pipeline/sub/leaf.py",
            "pipeline/zeta.py",
        )
    finally:
        dag.code_deps.cache_clear()


#: the geometry stages: the object and its candidates, before any trial
GEOMETRY_STAGES = ("sample", "medial_axis", "mat", "sphere_grid", "classify", "concavity", "candidates")


def test_geometry_stages_depend_on_no_trial_physics_or_export_code():
    # an engine, check or export change must not rerun the object's geometry
    engine_side = ("pipeline/trial/", "pipeline/checks/", "pipeline/bullet.py", "pipeline/outputs/")
    drawing = {"pipeline/outputs/__init__.py", "pipeline/outputs/recording.py", "pipeline/outputs/colours.py"}
    for name in GEOMETRY_STAGES:
        deps = set(dag.code_deps(name))
        assert {path for path in deps if path.startswith(engine_side)} <= drawing, name
        assert f"pipeline/geometry/{dag.function(dag.stage(name)).__module__.split('.')[-1]}.py" in deps
    assert {entry.name for entry in dag.STAGES if not entry.per_hand} - set(GEOMETRY_STAGES) == {"decompose"}
    # the recordings of the geometry stages draw no trial
    assert "pipeline/outputs/trial_recording.py" in dag.code_deps("simulate")


def test_code_deps_follow_the_imports_and_stay_tight():
    simulate = set(dag.code_deps("simulate"))
    # the trial engine's modules reach simulate through pipeline.trial.protocol -> engine
    assert {
        "pipeline/trial/__init__.py",
        "pipeline/trial/protocol.py",
        "pipeline/trial/engine.py",
        "pipeline/trial/proximity.py",
        "pipeline/geometry/mesh_query.py",
        "pipeline/trial/contacts.py",
        "pipeline/trial/quality.py",
        "pipeline/hands/kinematics.py",
        "pipeline/hands/urdf.py",
        "pipeline/params.py",
        "pipeline/stage_io.py",
        "pipeline/artefacts.py",
    } <= simulate
    assert not {path for path in simulate if path.startswith("pipeline/checks/")}
    assert {"pipeline/geometry/mat.py", "pipeline/geometry/cell_grid.py"} <= set(dag.code_deps("mat"))
    assert "pipeline/outputs/figures.py" in dag.code_deps("report") and "pipeline/outputs/figures.py" not in simulate
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
    quality = (dag.ROOT / "pipeline" / "trial" / "quality.py").read_bytes()
    assert written["files"]["pipeline/trial/quality.py"] == hashlib.md5(quality).hexdigest()


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
    # the convex parts: once per object, from the first scale's surface; each scale's check scales them
    decompose = yaml.safe_load((tmp_path / "dag/decompose/ring/dvc.yaml").read_text())["stages"]["decompose"]
    assert "matrix" not in decompose and decompose["deps"][1:] == ["data/ring/${scales[0]}/surface.npz"]
    assert decompose["outs"][0] == "data/ring/parts.npz" and " ${scales[0]} data/ring/parts.npz " in decompose["cmd"]
    check = yaml.safe_load((tmp_path / "dag/check/ring/dvc.yaml").read_text())["stages"]["check"]
    assert "data/ring/parts.npz" in check["deps"] and " data/ring/parts.npz ${item.scale} ${item.hand} " in check["cmd"]
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

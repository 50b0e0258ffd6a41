"""`python -m pipeline export`: the files' datasets and shapes, the ranking, the pre-grasp, and
every exported grasp replayed through the trial engine from the file alone giving its recorded
outcome and epsilon; the four run layouts (plan, DVC data/, report/, batch) and one-line errors."""

import json
import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pandas as pd
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from pipeline.__main__ import main
from pipeline.artefacts import SurfaceSamples, write_table
from pipeline.checks.protocol import with_checks
from pipeline.hands.kinematics import hand_model
from pipeline.hands.spec import export_hand, get_hand, load_hand
from pipeline.outputs.export import EXPORTED, closed_poses, rank_order
from pipeline.outputs.export_files import read_grasps
from pipeline.outputs.export_runs import find_runs
from pipeline.outputs.replay import replay_file
from pipeline.params import CheckParams, Params, SampleParams, SimulateParams
from pipeline.plan import run_chain, summary, write_plan
from pipeline.trial.engine import GraspEngine

REPO = Path(__file__).resolve().parents[1]
HANDS = ("armar3", "barrett")
SOURCE = "primitive:box"  # the default 10 x 6 x 2 cm box: what a batch rebuilds from the same source
PARAMS = Params(
    sample=SampleParams(count=4000),
    simulate=SimulateParams(spheres_per_object=2, baseline_trials=8, workers=1),
    checks=CheckParams(trials=3, robust_samples=4),
)
SETTINGS = PARAMS.simulate


@pytest.fixture(scope="module")
def plan_dir(tmp_path_factory):
    """A ``plan --out`` folder: the box, both hands, 2 spheres and 8 baseline trials each, 3 checked per planner."""
    artefacts, timings = run_chain(SOURCE, PARAMS, seed=3, hands=list(HANDS), simulate=True, workers=1)
    out = tmp_path_factory.mktemp("plan")
    write_plan(out, artefacts, summary(artefacts, timings, source=SOURCE, scale=1.0, seed=3, hands=list(HANDS)))
    return out


@pytest.fixture(scope="module")
def data_dir(plan_dir, tmp_path_factory):
    """The same trials as a DVC data/ tree: data/box/1.0/surface.npz, data/box/1.0/<hand>/{trials,checks}.parquet;
    armar3's trials get one extra ``collision`` and one ``error`` row (not exported, counted)."""
    trials, checks = pd.read_parquet(plan_dir / "trials.parquet"), pd.read_parquet(plan_dir / "checks.parquet")
    data = tmp_path_factory.mktemp("project") / "data"
    run = data / "box" / "1.0"
    run.mkdir(parents=True)
    shutil.copy(plan_dir / "surface.npz", run / "surface.npz")
    for hand in HANDS:
        rows = np.flatnonzero(trials.hand == hand)
        own = trials.iloc[rows].reset_index(drop=True)
        if hand == "armar3":
            failed = own.iloc[[0, 0]].copy()
            failed["outcome"] = ["collision", "error"]
            own = pd.concat([own, failed], ignore_index=True)
            own["outcome"] = pd.Categorical(own.outcome.astype(str), categories=trials.outcome.cat.categories)
        checked = checks[checks.hand == hand].copy()
        checked["trial"] = np.searchsorted(rows, checked.trial.to_numpy())  # rows of the hand's own table
        write_table(run / hand / "trials.parquet", own)
        write_table(run / hand / "checks.parquet", checked)
    return data


def export(run_dir, fmt, out, *extra):
    main(["export", str(run_dir), "--format", fmt, "--out", str(out), *extra])
    return sorted(Path(out).glob(f"*.{'h5' if fmt == 'acronym' else 'json'}"))


def source_rows(plan_dir, hand):
    """The plan's trials of ``hand`` with the checks on them and their row numbers in ``trial``."""
    trials = with_checks(pd.read_parquet(plan_dir / "trials.parquet"), pd.read_parquet(plan_dir / "checks.parquet"))
    trials["trial"] = np.arange(len(trials))
    return trials[trials.hand == hand]


def expected_ranking(rows):
    """Trial numbers of the closed trials in the documented order, by Python's sort on one key per trial."""

    def key(row):
        held = row.physics_success
        physics = 1 if pd.isna(held) else (0 if held else 2)
        robust = row.robust_fc
        return (
            row.outcome != "force_closure",
            physics,
            pd.isna(robust),
            0 if pd.isna(robust) else -robust,
            -row.epsilon,
        )

    closed = rows[rows.outcome.astype(str).isin(EXPORTED)]
    return [row.trial for row in sorted(closed.itertuples(), key=lambda row: (key(row), row.trial))]


def read_h5(path):
    """The grasps of an exported HDF5 file by plain h5py, as a robot-side reader would."""
    with h5py.File(path, "r") as h5:
        return {
            "transforms": h5["grasps/transforms"][()],
            "pregrasp": h5["grasps/pregrasp_transforms"][()],
            "joints": h5["grasps/joints"][()],
            "joint_names": tuple(h5["grasps/joint_names"].asstr()[()]),
            "success": h5["grasps/qualities/flex/object_in_gripper"][()],
            "epsilon": h5["grasps/qualities/epsilon"][()],
            "force_closure": h5["grasps/qualities/force_closure"][()],
            "physics_success": h5["grasps/qualities/physics_success"][()],
            "robust_fc": h5["grasps/qualities/robust_fc"][()],
            "outcome": list(h5["grasps/outcome"].asstr()[()]),
            "planner": list(h5["grasps/planner"].asstr()[()]),
            "trial": h5["grasps/trial"][()],
            "approach_m": h5["grasps/approach_m"][()],
            "hand": h5["gripper/type"].asstr()[()],
            "object_file": path.parent / h5["object/file"][()].decode("utf-8"),  # as ACRONYM's loader reads it
            "scale": h5["object/scale"][()],
            "vertices": h5["object/vertices"][()],
            "faces": h5["object/faces"][()],
            "attrs": dict(h5.attrs),
            "standoff": float(h5.attrs["standoff_m"]),
        }


def read_json(path):
    """The same from an exported JSON document by the json module alone."""
    document = json.loads(path.read_text())
    names = tuple(document["hand"]["joint_names"])
    grasps = document["grasps"]
    mesh = trimesh.load(path.parent / document["object"]["file"], process=False, force="mesh")
    return {
        "transforms": np.array([grasp["pose"] for grasp in grasps]).reshape(-1, 4, 4),
        "pregrasp": np.array([grasp["pregrasp_pose"] for grasp in grasps]).reshape(-1, 4, 4),
        "joints": np.array([[grasp["joints"][name] for name in names] for grasp in grasps]).reshape(-1, len(names)),
        "joint_names": names,
        "epsilon": np.array([grasp["epsilon"] for grasp in grasps], float),
        "physics_success": np.array(
            [np.nan if g["physics_success"] is None else g["physics_success"] for g in grasps], float
        ),
        "robust_fc": np.array([np.nan if g["robust_fc"] is None else g["robust_fc"] for g in grasps], float),
        "outcome": [grasp["outcome"] for grasp in grasps],
        "planner": [grasp["planner"] for grasp in grasps],
        "trial": np.array([grasp["trial"] for grasp in grasps], np.int64),
        "rank": [grasp["rank"] for grasp in grasps],
        "approach_m": np.array([grasp["approach_m"] for grasp in grasps], float),
        "hand": document["hand"]["name"],
        "vertices": np.asarray(mesh.vertices) * document["object"]["scale"],
        "faces": np.asarray(mesh.faces),
        "document": document,
        "standoff": document["standoff_m"],
    }


def assert_replays(found):
    """Every grasp replayed through GraspEngine.replay from the file's own mesh, pose and joints
    gives the recorded outcome, and epsilon within 1e-9 relative."""
    engine = GraspEngine(
        SimpleNamespace(vertices=found["vertices"], faces=found["faces"]), get_hand(found["hand"]), SETTINGS
    )
    results = engine.replay(found["transforms"], found["joints"])
    assert [result.outcome for result in results] == list(found["outcome"])
    np.testing.assert_allclose([result.epsilon for result in results], found["epsilon"], rtol=1e-9, atol=0)


def test_rank_order_known_answer():
    # (force closure, physics 1/0/NaN, robust_fc, epsilon) of six grasps, in the order the rule gives by hand:
    # the force closures (0..3) before the rest; among them held (1, 3) before unchecked (0) before failed
    # (2); held ones by robust_fc (3 has 0.9, 1 has 0.5); the two without force closure tie on physics
    # and robust_fc, so epsilon decides (5: 0.01 before 4: 0.0)
    force_closure = np.array([True, True, True, True, False, False])
    physics = np.array([np.nan, 1.0, 0.0, 1.0, np.nan, np.nan])
    robust = np.array([0.9, 0.5, 1.0, 0.9, np.nan, np.nan])
    epsilon = np.array([0.3, 0.1, 0.2, 0.05, 0.0, 0.01])
    inputs = [force_closure.copy(), physics.copy(), robust.copy(), epsilon.copy()]
    assert rank_order(force_closure, physics, robust, epsilon).tolist() == [3, 1, 0, 2, 5, 4]
    # robust_fc unchecked goes after every checked value, and a tie keeps the given order
    assert rank_order([True] * 3, [np.nan] * 3, [np.nan, 0.0, np.nan], [0.1, 0.1, 0.1]).tolist() == [1, 0, 2]
    for given, kept in zip((force_closure, physics, robust, epsilon), inputs):
        np.testing.assert_array_equal(given, kept)  # inputs not modified


def test_replay_grades_a_closed_hand_as_its_trial_did(plan_dir):
    surface = SurfaceSamples.load(plan_dir / "surface.npz")
    hand = get_hand("barrett")
    trials = pd.read_parquet(plan_dir / "trials.parquet")
    rows = trials[trials.hand == "barrett"].reset_index(drop=True)
    engine = GraspEngine(surface, hand, SETTINGS)
    candidate = [rows[[f"{name}_{axis}" for axis in "xyz"]].to_numpy() for name in ("grasp", "approach", "orient")]
    ran = engine.run(*candidate, list(rows.preshape))
    joints = np.stack(rows.joints.to_numpy())
    inputs = (closed_poses(rows, hand), joints.copy())
    replayed = engine.replay(*inputs)
    np.testing.assert_array_equal(inputs[1], joints)  # not modified
    assert [result.outcome for result in ran] == rows.outcome.astype(str).tolist()  # the plan's trials, again
    for trial, again in zip(ran, replayed):
        assert (again.outcome, again.epsilon, again.touched) == (trial.outcome, trial.epsilon, trial.touched)
        assert again.base_position == trial.base_position and again.joint_positions == trial.joint_positions
        np.testing.assert_array_equal(again.contact_points, trial.contact_points)
        np.testing.assert_array_equal(again.contact_links, trial.contact_links)
        assert again.finger_stops == ("contact",) * 3 and np.isnan(again.retract_m) and np.isnan(again.approach_m)
    far = inputs[0][:1].copy()
    far[0, :3, 3] += [1.0, 0.0, 0.0]  # a metre off the 10 cm box: touches nothing
    (alone,) = engine.replay(far, joints[:1])
    assert alone.outcome == "no_contact" and alone.epsilon == 0.0 and not alone.touched


@pytest.mark.parametrize("fmt", ["acronym", "json"])
def test_plan_export_datasets_ranking_pregrasp_and_replay(plan_dir, tmp_path, fmt, capsys):
    files = export(plan_dir, fmt, tmp_path / "out", "--standoff", "0.07")
    printed = capsys.readouterr().out.splitlines()
    assert [path.name for path in files] == [f"box-1.0-{hand}.{'h5' if fmt == 'acronym' else 'json'}" for hand in HANDS]
    assert len(printed) == 3 and printed[-1].startswith(f"export {plan_dir} -> {tmp_path / 'out'}: 2 files, ")
    assert (tmp_path / "out" / "box-1.0.obj").is_file() and (tmp_path / "out" / "armar3.urdf").is_file()
    surface = np.load(plan_dir / "surface.npz")
    for path, hand in zip(files, HANDS):
        found = read_h5(path) if fmt == "acronym" else read_json(path)
        rows = source_rows(plan_dir, hand)
        count = int(rows.outcome.astype(str).isin(EXPORTED).sum())
        model = hand_model(get_hand(hand))
        # shapes and names: joints in the hand model's order, which is the hand's limits order
        assert found["transforms"].shape == found["pregrasp"].shape == (count, 4, 4)
        assert found["joints"].shape == (count, len(model.joints))
        assert found["joint_names"] == model.joints == tuple(get_hand(hand).limits)
        assert len(found["outcome"]) == len(found["planner"]) == len(found["epsilon"]) == len(found["trial"]) == count
        assert set(found["planner"]) <= set(rows.planner) and found["hand"] == hand
        # the mesh: file x scale is the simulated mesh, bit for bit at scale 1
        np.testing.assert_array_equal(found["vertices"], surface["vertices"])
        np.testing.assert_array_equal(found["faces"], surface["faces"])
        # ranked by the documented rule (an independent sort of the plan's own rows)
        assert found["trial"].tolist() == expected_ranking(rows)
        by_trial = rows.set_index("trial").loc[found["trial"]]
        assert found["outcome"] == by_trial.outcome.astype(str).tolist()
        np.testing.assert_array_equal(found["epsilon"], by_trial.epsilon.to_numpy())
        # the checks where checked, NaN elsewhere
        np.testing.assert_array_equal(found["robust_fc"], by_trial.robust_fc.to_numpy(float))
        held = by_trial.physics_success.astype("boolean").astype("Float64").to_numpy(float, na_value=np.nan)
        np.testing.assert_array_equal(found["physics_success"], held)
        assert 0 < np.isfinite(found["robust_fc"]).sum() < count
        # the closed pose is the trial's recorded base pose
        np.testing.assert_array_equal(
            found["transforms"][:, :3, 3], by_trial[["base_x", "base_y", "base_z"]].to_numpy()
        )
        rotations = by_trial[[f"base_q{axis}" for axis in "xyzw"]].to_numpy()
        np.testing.assert_allclose(
            found["transforms"][:, :3, :3], Rotation.from_quat(rotations).as_matrix(), atol=1e-12
        )
        np.testing.assert_array_equal(found["transforms"][:, 3], [[0, 0, 0, 1]] * count)
        # the pre-grasp: the same orientation, -(approach_m + standoff) along the unit approach
        approach = by_trial[["approach_x", "approach_y", "approach_z"]].to_numpy()
        approach = approach / np.linalg.norm(approach, axis=1, keepdims=True)
        back = by_trial.approach_m.to_numpy() + 0.07
        assert found["standoff"] == 0.07
        np.testing.assert_array_equal(found["approach_m"], by_trial.approach_m.to_numpy())
        np.testing.assert_array_equal(found["pregrasp"][:, :3, :3], found["transforms"][:, :3, :3])
        np.testing.assert_allclose(
            found["pregrasp"][:, :3, 3], found["transforms"][:, :3, 3] - back[:, None] * approach, rtol=0, atol=1e-15
        )
        assert_replays(found)
        if fmt == "acronym":
            np.testing.assert_array_equal(found["success"], np.array(found["outcome"]) == "force_closure")
            np.testing.assert_array_equal(found["force_closure"], found["success"] == 1)
            assert found["scale"] == 1.0 and found["object_file"].name == "box-1.0.obj"
            obj = trimesh.load(found["object_file"], process=False, force="mesh")
            np.testing.assert_array_equal(np.asarray(obj.vertices) * found["scale"], found["vertices"])
            attrs = found["attrs"]
            assert attrs["trials"] == len(rows) and attrs["skipped_collision"] == 0
            assert "force closure" in attrs["ranking"] and "T_object_hand" in attrs["transform"]
        else:
            document = found["document"]
            assert found["rank"] == list(range(1, count + 1))
            assert document["hand"]["urdf"] == f"{hand}.urdf" and document["hand"]["approach"] == [0.0, 0.0, 1.0]
            assert document["object"] == {"name": "box", "file": "box-1.0.obj", "scale": 1.0}
            assert document["skipped"] == {"collision": 0, "step_cap": 0, "error": 0} and document["trials"] == len(
                rows
            )


def test_read_grasps_and_replay_file_agree_on_both_formats(plan_dir, tmp_path):
    h5_file = export(plan_dir, "acronym", tmp_path / "h5")[0]
    json_file = export(plan_dir, "json", tmp_path / "json")[0]
    from_h5, from_json = read_grasps(h5_file), read_grasps(json_file)
    for key in (
        "transforms",
        "pregrasp_transforms",
        "joints",
        "pregrasp_joints",
        "epsilon",
        "trial",
        "physics_success",
    ):
        np.testing.assert_array_equal(from_h5[key], from_json[key])
    assert list(from_h5["outcome"]) == list(from_json["outcome"]) and from_h5["joint_names"] == from_json["joint_names"]
    # the open preshape's joints at the pre-grasp
    hand = get_hand(from_h5["hand"])
    np.testing.assert_array_equal(from_h5["pregrasp_joints"][0], [hand.preshape()[j] for j in from_h5["joint_names"]])
    found, results = replay_file(json_file, settings=SETTINGS)
    assert [result.outcome for result in results] == list(found["outcome"])
    assert all(result.finger_stops == ("contact",) * len(hand.fingers) for result in results)
    assert json_file.read_bytes() == export(plan_dir, "json", tmp_path / "again")[0].read_bytes()  # deterministic


def test_dvc_data_tree_counts_skipped_trials(data_dir, tmp_path, capsys):
    runs = find_runs(data_dir.parent)  # the project root: finds data/ below it
    assert [(run.object, run.scale, run.hand) for run in runs] == [("box", 1.0, hand) for hand in HANDS]
    files = export(data_dir, "acronym", tmp_path / "out")
    assert "skipped: collision 1, step_cap 0, error 1" in capsys.readouterr().out
    found = read_h5(files[0])
    assert found["attrs"]["skipped_collision"] == 1 and found["attrs"]["skipped_error"] == 1
    assert found["attrs"]["trials"] == len(pd.read_parquet(data_dir / "box/1.0/armar3/trials.parquet"))
    assert "collision" not in found["outcome"] and "error" not in found["outcome"]
    assert np.isfinite(found["robust_fc"]).sum() > 0  # the hand's own checks table, on its own rows
    for path in files:
        assert_replays(read_h5(path))


def test_report_layout_finds_meshes_in_the_data_tree(plan_dir, data_dir, tmp_path):
    from pipeline.outputs.report import combine

    tables, checks = {}, {}
    for name in ("box", "block"):  # two objects, the second with a planner the first has not
        if name == "block":
            shutil.copytree(data_dir / "box", data_dir / "block", dirs_exist_ok=True)
        for hand in HANDS:
            trials = pd.read_parquet(data_dir / name / "1.0" / hand / "trials.parquet")
            checked = pd.read_parquet(data_dir / name / "1.0" / hand / "checks.parquet")
            if name == "block":
                trials["planner"] = trials.planner.replace("baseline", "encompassing")
                checked["planner"] = checked.planner.replace("baseline", "encompassing")
            tables[(name, 1.0, hand)], checks[(name, 1.0, hand)] = trials, checked
    report = data_dir.parent / "report"
    write_table(report / "trials.parquet", combine(tables, checks))
    files = export(report, "json", tmp_path / "out")
    assert [path.name for path in files] == [f"{name}-1.0-{hand}.json" for name in ("block", "box") for hand in HANDS]
    found = read_json(files[0])
    assert "encompassing" in found["planner"] and np.isfinite(found["robust_fc"]).any()
    assert found["document"]["skipped"]["collision"] == 1
    for path in files:
        assert_replays(read_json(path))
    shutil.rmtree(data_dir / "block")


def test_batch_output_rebuilds_the_mesh_at_its_scale(plan_dir, tmp_path, capsys):
    trials = with_checks(pd.read_parquet(plan_dir / "trials.parquet"), pd.read_parquet(plan_dir / "checks.parquet"))
    batch = tmp_path / "batch"
    write_table(batch / "trials" / "box.parquet", trials.assign(object="box")[["object", *trials.columns]])
    write_table(
        batch / "objects" / "box.parquet", pd.DataFrame({"object": ["box"], "source": [SOURCE], "status": ["ok"]})
    )
    # trials written before the batch stopped, without the summary row that marks the object done
    write_table(batch / "trials" / "ghost.parquet", trials.assign(object="ghost")[["object", *trials.columns]])
    files = export(batch, "acronym", tmp_path / "out")
    assert [path.name for path in files] == [f"box-1.0-{hand}.h5" for hand in HANDS]
    err = capsys.readouterr().err
    assert (
        err
        == f"warning: {batch / 'trials' / 'ghost.parquet'}: left out, object 'ghost' is not done in {batch / 'objects'}\n"
    )
    for path in files:
        assert_replays(read_h5(path))
    with pytest.raises(SystemExit) as stop:
        export(batch, "acronym", tmp_path / "half", "--scale", "0.5")
    err = capsys.readouterr().err
    assert stop.value.code == 2 and err.count("\n") == 1 and "give the batch's --scale" in err


def test_help_describes_the_command_with_examples(capsys):
    with pytest.raises(SystemExit) as exited:
        main(["export", "--help"])
    text = capsys.readouterr().out
    assert exited.value.code == 0 and "--standoff" in text and "(default: 0.05)" in " ".join(text.split())
    assert text.split("example:\n", 1)[1].splitlines()[0].strip().startswith("python -m pipeline export ")


def test_bad_inputs_give_one_line(data_dir, tmp_path, capsys):
    def fails(*argv):
        with pytest.raises(SystemExit) as stop:
            main(["export", *argv])
        return stop.value.code, capsys.readouterr().err

    code, err = fails(str(tmp_path / "nope"), "--format", "json", "--out", str(tmp_path / "out"))
    assert code == 2 and err == f"error: {tmp_path / 'nope'}: no such folder\n"
    (tmp_path / "empty").mkdir()
    code, err = fails(str(tmp_path / "empty"), "--format", "json", "--out", str(tmp_path / "out"))
    assert code == 2 and err.startswith(f"error: {tmp_path / 'empty'}: holds no trials") and err.count("\n") == 1
    code, err = fails(str(data_dir), "--format", "csv", "--out", str(tmp_path / "out"))
    assert code == 2 and "argument --format: invalid choice: 'csv'" in err and "Traceback" not in err
    code, err = fails(str(data_dir), "--format", "json", "--out", str(tmp_path / "out"), "--standoff", "-1")
    assert code == 2 and err == "error: export: standoff must be a distance >= 0 m, got -1.0\n"
    # a hand no one knows: one line naming it, nothing written
    strange = tmp_path / "strange" / "box" / "1.0"
    shutil.copytree(data_dir / "box" / "1.0", strange)
    trials = pd.read_parquet(strange / "barrett" / "trials.parquet")
    write_table(strange / "barrett" / "trials.parquet", trials.assign(hand="robotiq"))
    code, err = fails(str(tmp_path / "strange"), "--format", "acronym", "--out", str(tmp_path / "out"))
    assert code == 2 and err.count("\n") == 1 and "unknown hand 'robotiq' in the trials" in err
    assert not (tmp_path / "out").exists()
    # ... which its spec names: the Barrett's URDF and declarations under that name
    spec = export_hand(get_hand("barrett"), tmp_path / "spec")
    spec.write_text(spec.read_text().replace("name: barrett", "name: robotiq"))
    (file,) = export(tmp_path / "strange", "json", tmp_path / "out", "--hand", str(spec))[1:]
    found, results = replay_file(file, hand=load_hand(spec), settings=SETTINGS)
    assert file.name == "box-1.0-robotiq.json" and found["hand"] == "robotiq" and len(results) > 0
    assert [result.outcome for result in results] == list(found["outcome"])
    # and through the real command line: one line on stderr, no traceback
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", "export", str(tmp_path / "nope"), "--format", "acronym", "--out", "x"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(REPO), "PATH": str(Path(sys.executable).parent)},
    )
    assert result.returncode == 2 and result.stderr == f"error: {tmp_path / 'nope'}: no such folder\n"

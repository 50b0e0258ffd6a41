"""`medial-grasp evaluate` (pipeline.outputs.grasp_sets, pipeline.outputs.evaluate): ACRONYM-layout files written
here by hand in ACRONYM's Panda frame, the frame rule tested by its failure, the agreement table's
known answers, and one-line errors for bad files with nothing written."""

import json

import h5py
import numpy as np
import pandas as pd
import pytest
import trimesh

from pipeline.__main__ import main
from pipeline.hands.kinematics import hand_model, link_poses
from pipeline.hands.spec import get_hand
from pipeline.outputs.evaluate import confusion, roc_auc
from pipeline.outputs.replay import replay_file
from pipeline.outputs.grasp_sets import GRIPPER_FRAMES, read_grasp_set
from pipeline.params import CheckParams, Params, SampleParams, SimulateParams
from pipeline.plan import run_chain, summary, write_plan

#: ACRONYM's Panda frame over a 4 cm cube centred at the origin: approach +z pointing down
#: (-z world), fingers along +-x (world x), its grasp point 105 mm along +z on the cube's centre
ON_CUBE = np.array([[1.0, 0, 0, 0], [0, -1.0, 0, 0], [0, 0, -1.0, 0.105], [0, 0, 0, 1.0]])
BESIDE = ON_CUBE.copy()
BESIDE[1, 3] = 0.05  # 5 cm off the cube along world y, across the fingers' motion: nothing between them


def write_acronym(path, transforms, labels=None, *, extents=(0.04, 0.04, 0.04), gripper="panda", **extra):
    """An ACRONYM-layout file as the dataset ships it (mesh beside it, mass, friction, label)."""
    mesh = path.with_suffix(".obj")
    trimesh.creation.box(extents=extents).export(mesh)
    with h5py.File(path, "w") as h5:
        if transforms is not None:
            h5["grasps/transforms"] = np.asarray(transforms, np.float64)
        h5["object/file"] = extra.get("file") or mesh.name
        h5["object/scale"] = 1.0
        h5["object/mass"] = 0.05
        h5["object/friction"] = 0.5
        h5["gripper/type"] = gripper
        h5["gripper/configuration"] = np.array([0.04])
        if labels is not None:
            h5["grasps/qualities/flex/object_in_gripper"] = np.asarray(labels, np.int64)
    return path


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """``plan`` on the 10 x 6 x 2 cm box with franka and parallel_jaw (4 spheres, 16 baseline
    trials each), then ``export --format acronym``: {hand: exported HDF5 file}."""
    hands = ["franka", "parallel_jaw"]
    params = Params(
        sample=SampleParams(count=4000),
        simulate=SimulateParams(spheres_per_object=4, baseline_trials=16, workers=1),
        checks=CheckParams(trials=0),
    )
    artefacts, timings = run_chain("primitive:box", params, seed=3, hands=hands, simulate=True, workers=1)
    root = tmp_path_factory.mktemp("round_trip")
    write_plan(
        root / "plan", artefacts, summary(artefacts, timings, source="primitive:box", scale=1.0, seed=3, hands=hands)
    )
    main(["export", str(root / "plan"), "--format", "acronym", "--out", str(root / "export")])
    return {hand: root / "export" / f"box-1.0-{hand}.h5" for hand in hands}


def evaluate(path, out, *extra):
    main(["evaluate", str(path), "--out", str(out), "--workers", "1", *extra])
    return pd.read_parquet(out / "labels.parquet")


def test_a_panda_grasp_in_acronyms_frame_holds_the_cube_and_one_beside_it_has_no_grasp(tmp_path, capsys):
    """The pads close on the cube's faces x = +-2 cm: force closure, held (50 g, mu 0.5); 5 cm
    beside it the fingers close on nothing. Labels 1 / 0 make both verdicts right."""
    path = write_acronym(tmp_path / "cube.h5", [ON_CUBE, BESIDE], [1, 0])
    labels = evaluate(path, tmp_path / "out")
    assert labels.grasp.tolist() == [0, 1]
    assert labels.outcome.tolist() == ["force_closure", "no_contact"]
    for check in ("physics", "mujoco", "mujoco_open"):  # pybullet, MuJoCo from the closed pose and from the open hand
        assert labels[f"{check}_outcome"].tolist() == ["held", "no_grasp"]
    assert set(labels.touched[0].split(",")) >= {"panda_leftfinger", "panda_rightfinger"}
    assert labels.robust_fc[0] > 0.5 and labels.robust_fc[1] == 0.0
    found = json.loads((tmp_path / "out" / "agreement.json").read_text())
    for verdict in ("force_closure", "physics_success", "mujoco_success", "mujoco_open_success", "robust_fc"):
        row = found["verdicts"][verdict]
        assert (row["tp"], row["fp"], row["fn"], row["tn"], row["balanced_accuracy"]) == (1, 0, 0, 1, 1.0)
    assert found["mass_kg"] == 0.05 and found["mu"] == 0.5 and found["engines"] == ["mujoco", "pybullet"]
    assert "force closure" in capsys.readouterr().out
    # the labelled copy: the file's own datasets untouched, ours beside them
    with h5py.File(path) as original, h5py.File(tmp_path / "out" / "cube.h5") as labelled:
        assert np.array_equal(labelled["grasps/transforms"][()], original["grasps/transforms"][()])
        assert labelled["grasps/qualities/flex/object_in_gripper"][()].tolist() == [1, 0]
        ours = labelled["grasps/qualities/medial_grasp"]
        assert ours["force_closure"][()].tolist() == [1.0, 0.0]
        assert ours["physics_success"][()].tolist() == [1.0, 0.0]
        assert ours["mujoco_open_success"][()].tolist() == [1.0, 0.0]
        assert [value.decode() for value in ours["mujoco_outcome"][()]] == ["held", "no_grasp"]
        assert [value.decode() for value in ours["outcome"][()]] == ["force_closure", "no_contact"]


def test_the_panda_frame_is_the_franka_base_turned_90_degrees_about_the_approach(tmp_path):
    """On a 4 x 12 x 4 cm bar the ACRONYM-frame pose grips the 4 cm across; the same pose written
    in pybullet's panda_hand frame (fingers along y: the old export's frame) puts the fingers
    along the 12 cm, wider than the 8 cm opening, and the placed hand overlaps the bar."""
    wrong = ON_CUBE @ GRIPPER_FRAMES["panda"][1]
    path = write_acronym(tmp_path / "bar.h5", [ON_CUBE, wrong], [1, 1], extents=(0.04, 0.12, 0.04))
    grasps = read_grasp_set(path)
    assert grasps.hand.name == "franka"
    # the base frame's y (pybullet's finger axis) is the gripper's -x (Rz(+90 deg) takes y to -x)
    assert np.array_equal(grasps.base[0, :3, 1], -ON_CUBE[:3, 0])
    assert np.array_equal(grasps.base[0, :3, 2], ON_CUBE[:3, 2])  # the same approach
    labels = evaluate(path, tmp_path / "out")
    assert labels.outcome.tolist() == ["force_closure", "collision"]
    assert labels.physics_success.tolist() == [True, False]


@pytest.mark.parametrize("hand", ["franka", "parallel_jaw"])
def test_plan_export_evaluate_gives_back_every_trials_outcome(exported, tmp_path, hand):
    """Every exported grasp, closed in place from its file's pose and open joints, ends as its
    trial did: the same outcome and joints, bit for bit (the pose moves through the gripper frame
    and back exactly), and epsilon; the agreement with the file's label (the recorded force
    closure) is therefore perfect."""
    path = exported[hand]
    labels = evaluate(path, tmp_path / "out")
    with h5py.File(path) as h5:
        recorded = h5["grasps/outcome"].asstr()[()].tolist()
        epsilon, joints = h5["grasps/qualities/epsilon"][()], h5["grasps/joints"][()]
    assert len(labels) == len(recorded) >= 20
    assert {"force_closure", "no_force_closure"} <= set(recorded)  # both kinds tried
    assert labels.outcome.tolist() == recorded
    # epsilon to 1e-12: another batch of grasps can sum the same hull in another order (2e-16 seen)
    np.testing.assert_allclose(labels.epsilon, epsilon, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(np.stack(labels.joints), joints)
    found = json.loads((tmp_path / "out" / "agreement.json").read_text())
    assert found["verdicts"]["force_closure"]["balanced_accuracy"] == 1.0


def test_franka_is_exported_as_acronyms_panda_with_the_fingers_along_x(exported):
    """The franka file holds gripper/type "panda", configuration [0.04] (each finger's opening)
    and poses in ACRONYM's frame: each closed finger's link origin, seen from the file's gripper
    frame, lies on the x axis at its joint value, one finger each side (pybullet's panda_hand moves them
    along its y), 58.4 mm along the approach +z."""
    with h5py.File(exported["franka"]) as h5:
        assert h5["gripper/type"].asstr()[()] == "panda"
        assert h5["gripper/configuration"][()].tolist() == [0.04]
        transforms, joints = h5["grasps/transforms"][()], h5["grasps/joints"][()]
        base = h5["grasps/transforms"][()] @ h5["gripper/T_gripper_base"][()]
    model = hand_model(get_hand("franka"))
    fingers = [model.links.index(name) for name in ("panda_leftfinger", "panda_rightfinger")]
    links = link_poses(model, base, joints)[:, fingers]
    in_gripper = np.linalg.inv(transforms)[:, None] @ links  # (n, 2, 4, 4) T_gripper_finger
    origins = in_gripper[..., :3, 3]
    np.testing.assert_allclose(origins[..., 1], 0.0, atol=1e-12)
    # the left finger's joint opens it along the base's +y, the gripper's -x; the right one's along +x
    np.testing.assert_allclose(origins[..., 0], joints * [-1.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(origins[..., 2], 0.0584, atol=1e-12)
    # the project's own reader turns them back into the franka's base frame, bit for bit
    found, results = replay_file(exported["franka"], settings=SimulateParams())
    assert found["hand"] == "franka"
    np.testing.assert_array_equal(found["transforms"], base)
    assert [result.outcome for result in results] == list(found["outcome"])


def test_labels_do_not_depend_on_the_sample_or_the_workers(tmp_path):
    """Six grasps about the cube's vertical axis; a seeded sample of 3 labels its grasps as the
    whole run does, with 1 worker and with 2."""
    turns = [np.diag([np.cos(a), np.cos(a), 1, 1]) for a in np.linspace(0, np.pi, 6, endpoint=False)]
    for turn, angle in zip(turns, np.linspace(0, np.pi, 6, endpoint=False)):
        turn[0, 1], turn[1, 0] = -np.sin(angle), np.sin(angle)
    path = write_acronym(tmp_path / "cube.h5", [turn @ ON_CUBE for turn in turns])
    whole = evaluate(path, tmp_path / "all")
    assert (whole.outcome == "force_closure").sum() >= 2  # the face-on ones (0 and 90 deg)
    main(["evaluate", str(path), "--out", str(tmp_path / "two"), "--workers", "2", "--sample", "3"])
    part = pd.read_parquet(tmp_path / "two" / "labels.parquet")
    assert len(part) == 3
    columns = ["outcome", "epsilon", "robust_fc", "robust_epsilon", "physics_outcome", "physics_slip_m"]
    columns += ["mujoco_outcome", "mujoco_slip_m", "mujoco_open_outcome", "mujoco_open_slip_m"]
    pd.testing.assert_frame_equal(
        part[columns], whole.set_index("grasp").loc[part.grasp, columns].reset_index(drop=True)
    )
    assert not (tmp_path / "two" / "agreement.json").exists()  # no labels in the file


def test_one_engine_leaves_the_others_columns_empty_and_out_of_the_agreement(tmp_path):
    path = write_acronym(tmp_path / "cube.h5", [ON_CUBE, BESIDE], [1, 0])
    labels = evaluate(path, tmp_path / "out", "--engine", "pybullet")
    assert labels.physics_outcome.tolist() == ["held", "no_grasp"]
    assert (labels.mujoco_outcome == "").all() and (labels.mujoco_open_outcome == "").all()
    found = json.loads((tmp_path / "out" / "agreement.json").read_text())
    assert set(found["verdicts"]) == {"force_closure", "physics_success", "robust_fc"}
    with h5py.File(tmp_path / "out" / "cube.h5") as labelled:
        assert np.isnan(labelled["grasps/qualities/medial_grasp/mujoco_success"][()]).all()


def test_roc_auc_and_the_confusion_table_known_answers():
    """AUC of successes (0.9, 0.4) over failures (0.5, 0.1), by hand: of the 4 pairs 0.9 > 0.5,
    0.9 > 0.1, 0.4 > 0.1 are ordered right, 0.4 < 0.5 is not -> 3/4; a tie counts half."""
    assert roc_auc([0.9, 0.4, 0.5, 0.1], [1, 1, 0, 0]) == 0.75
    assert roc_auc([0.5, 0.5], [1, 0]) == 0.5
    assert np.isnan(roc_auc([0.1, 0.2], [1, 1]))
    table = confusion([1, 1, 0, 0, 1], [1, 0, 0, 1, 1])
    assert (table["tp"], table["fp"], table["fn"], table["tn"]) == (2, 1, 1, 1)
    assert table["precision"] == pytest.approx(2 / 3) and table["recall"] == pytest.approx(2 / 3)
    assert table["balanced_accuracy"] == pytest.approx((2 / 3 + 1 / 2) / 2)


NOT_RIGID = ON_CUBE.copy()
NOT_RIGID[:3, :3] *= 1.1  # a scaled rotation


@pytest.mark.parametrize(
    "case, why",
    [
        ("no_transforms", "has no grasps/transforms"),
        ("unknown_gripper", "unknown gripper/type 'robotiq_2f85'"),
        ("mesh_missing", "is not found"),
        ("not_rigid", "grasps/transforms[1] is not a rigid motion"),
        ("empty_file", "file is empty"),
        ("no_grasps", "holds no grasps"),
    ],
)
def test_a_bad_grasp_file_is_one_line_naming_it_and_nothing_is_written(tmp_path, capsys, case, why):
    path = tmp_path / f"{case}.h5"
    if case == "empty_file":
        path.write_bytes(b"")
    else:
        transforms = {"no_transforms": None, "not_rigid": [ON_CUBE, NOT_RIGID], "no_grasps": np.zeros((0, 4, 4))}
        write_acronym(
            path,
            transforms.get(case, [ON_CUBE]),
            gripper="robotiq_2f85" if case == "unknown_gripper" else "panda",
            file="elsewhere/mug.obj" if case == "mesh_missing" else None,
        )
    out = tmp_path / "out"
    with pytest.raises(SystemExit) as raised:
        main(["evaluate", str(path), "--out", str(out), "--workers", "1"])
    error = capsys.readouterr().err.strip()
    assert raised.value.code == 2 and len(error.splitlines()) == 1
    assert error.startswith(f"error: {path}") and why in error
    assert not out.exists()

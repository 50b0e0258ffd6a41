"""Recordings read back: the .rrd with rerun's RrdReader, the .mcap with the mcap reader."""

import json

import numpy as np
import pyarrow as pa
import pytest
import yaml
from mcap.reader import make_reader
from rerun.chunk import RrdReader

from conftest import complete_params
from pipeline.dag import STAGES
from pipeline.hands.kinematics import hand_boxes, hand_model
from pipeline.hands.spec import get_hand
from pipeline.logbook import file_digest, mcap_log, read_log
from pipeline.outputs.recording import rerun_recording
from pipeline.outputs.trial_recording import record_chain
from pipeline.params import CheckParams, Params, SampleParams, SimulateParams
from pipeline.plan import run_chain, summary

HANDS = ["armar3", "barrett"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("recorded")
    params = Params(
        sample=SampleParams(count=3000),
        simulate=SimulateParams(spheres_per_object=2, baseline_trials=3, workers=1),
        checks=CheckParams(trials=2, robust_samples=2),
    )
    artefacts, timings = run_chain("primitive:capsule", params, seed=0, hands=HANDS, simulate=True)
    result = summary(artefacts, timings, source="primitive:capsule", scale=1.0, seed=0)
    record_chain(
        folder / "capsule.rrd",
        folder / "capsule.mcap",
        artefacts,
        result,
        name="capsule",
        hands=[get_hand(hand) for hand in HANDS],
        settings=params.simulate,
    )
    artefacts["sample"].save(folder / "surface.npz")
    artefacts["sphere_grid"].save(folder / "sphere_grid.npz")
    return folder, artefacts


def rows_of(path, entity, timeline=False):
    """The record batches logged to ``entity`` in the .rrd at ``path``, concatenated (``timeline``:
    only those on a timeline, not static ones)."""
    batches = [
        chunk.to_record_batch()
        for chunk in RrdReader(path).stream()
        if chunk.entity_path == entity and not (timeline and chunk.is_static)
    ]
    assert batches, f"no chunk for {entity}"
    return pa.Table.from_batches(batches)


def instances(path, entity, column):
    table = rows_of(path, entity)
    return sum(len(value) for value in table.column(column).to_pylist() if value is not None)


def test_rrd_holds_every_sphere_candidate_and_one_step_per_trial(recorded):
    folder, artefacts = recorded
    path = folder / "capsule.rrd"
    assert instances(path, "/capsule/spheres", "Ellipsoids3D:centers") == len(artefacts["mat"])
    assert instances(path, "/capsule/reduced", "Points3D:positions") == len(artefacts["classify"])
    trials = artefacts["trials"]
    for hand in HANDS:
        candidates = artefacts["candidates"]
        assert instances(path, f"/capsule/candidates/{hand}/approach", "Arrows3D:vectors") == int(
            (candidates.hand == hand).sum()
        )
        steps = rows_of(path, f"/capsule/outcome/{hand}").column("trial").to_pylist()
        own = trials[trials.hand == hand].reset_index(drop=True)
        assert sorted(steps) == list(range(len(own))) and len(own) > 0
        # the hand's closed pose: one box per link at every trial
        closed = rows_of(path, f"/capsule/trials/{hand}/hand/closed", timeline=True)
        assert closed.num_rows == len(own)
        sizes = {len(value) for value in closed.column("Boxes3D:half_sizes").to_pylist()}
        assert sizes == {len(get_hand(hand).links)}
        # the last trial's closed boxes: its base pose and joints (by name) through the kinematics
        model, last = hand_model(get_hand(hand)), own.iloc[-1]
        named = dict(zip(get_hand(hand).limits, last.joints))
        centres, _, _ = hand_boxes(
            model,
            [[last.base_x, last.base_y, last.base_z]],
            [[last.base_qx, last.base_qy, last.base_qz, last.base_qw]],
            [[named.get(joint, 0.0) for joint in model.joints]],
        )
        drawn = dict(zip(closed.column("trial").to_pylist(), closed.column("Boxes3D:centers").to_pylist()))
        np.testing.assert_allclose(np.array(drawn[len(own) - 1]), centres[0], atol=1e-6)
        joints = rows_of(path, f"/capsule/trials/{hand}/joints")
        by_step = dict(zip(joints.column("trial").to_pylist(), joints.column("joints_rad").to_pylist()))
        assert by_step[len(own) - 1] == pytest.approx(list(own.joints.iloc[-1]))
        epsilon = rows_of(path, f"/capsule/epsilon/{hand}")
        by_step = dict(zip(epsilon.column("trial").to_pylist(), epsilon.column("Scalars:scalars").to_pylist()))
        assert [by_step[step][0] for step in range(len(own))] == pytest.approx(own.epsilon.tolist())


def test_mcap_counts_and_one_trial_match_the_trials_table(recorded):
    folder, artefacts = recorded
    with open(folder / "capsule.mcap", "rb") as stream:
        messages = [
            (channel.topic, json.loads(message.data), schema.encoding)
            for schema, channel, message in make_reader(stream).iter_messages()
        ]
    topics = [topic for topic, _, _ in messages]
    trials = artefacts["trials"]
    assert topics.count("/trials") == len(trials)
    assert topics[0] == "/stage" and messages[0][1] == {"stage": "plan", "event": "start"}
    assert messages[-1][1] == {"stage": "plan", "event": "end"}
    assert {encoding for _, _, encoding in messages} == {"jsonschema"}
    assert topics.count("/timing") == len(STAGES)  # every stage of the chain, one process
    logged = [payload for topic, payload, _ in messages if topic == "/trials"]
    row = trials.iloc[len(trials) // 2]
    sent = logged[len(trials) // 2]
    assert sent["outcome"] == row.outcome and sent["hand"] == row.hand and sent["planner"] == row.planner
    assert sent["epsilon"] == pytest.approx(row.epsilon) and sent["joints"] == pytest.approx(list(row.joints))
    assert [sent[f"base_{axis}"] for axis in "xyz"] == pytest.approx([row.base_x, row.base_y, row.base_z])


def test_mcap_messages_are_strict_json_without_nan(tmp_path):
    with mcap_log(tmp_path / "nan.mcap", "simulate") as log:
        log.log("/trials", {"epsilon": float("nan"), "base_x": np.float64("inf"), "joints": np.array([0.5, np.nan])})
    with open(tmp_path / "nan.mcap", "rb") as stream:
        raw = [message.data for _, _, message in make_reader(stream).iter_messages(topics=["/trials"])]
    assert json.loads(raw[0], parse_constant=lambda name: pytest.fail(f"{name} in JSON")) == {
        "epsilon": None,
        "base_x": None,
        "joints": [0.5, None],
    }


def test_an_interrupted_recording_leaves_nothing_under_its_name(tmp_path):
    import rerun as rr

    for opener, name in (
        (lambda path: rerun_recording(path, recording_id="x"), "broken.rrd"),
        (lambda path: mcap_log(path, "stage"), "broken.mcap"),
    ):
        with pytest.raises(KeyboardInterrupt):
            with opener(tmp_path / name) as stream:
                if name.endswith(".rrd"):
                    stream.log("/points", rr.Points3D(np.zeros((10, 3))))
                else:
                    stream.log("/warning", {"message": "half-way"})
                raise KeyboardInterrupt
        assert list(tmp_path.iterdir()) == []


def run_classify_stage(folder, monkeypatch, *, record, grid="sphere_grid.npz"):
    """The classify stage in ``folder`` (which gets a params.yaml with ``record``); returns its exit code."""
    from stages import classify

    monkeypatch.chdir(folder)
    (folder / "params.yaml").write_text(
        yaml.safe_dump(complete_params({"record": record, "classify": {"search_radius": 0.05}}))
    )
    try:
        classify.main(
            [
                grid,
                "surface.npz",
                "symmetry.npz",
                "--timing",
                "timing.json",
                "--log",
                "logs/classify.mcap",
                "--rrd",
                "logs/object.rrd",
                "--recording-id",
                "capsule-1.0",
            ]
        )
    except SystemExit as exit_:
        return exit_.code
    return 0


def test_a_stage_logs_hashes_counts_and_records_unless_turned_off(recorded, monkeypatch, capsys):
    folder, artefacts = recorded
    assert run_classify_stage(folder, monkeypatch, record=True) == 0
    messages = read_log(folder / "logs" / "classify.mcap")
    topics = [topic for topic, _ in messages]
    assert topics[0] == "/stage" and topics[-1] == "/stage" and topics.count("/params") == 1
    assert dict(messages)["/params"]["search_radius"] == 0.05
    hashed = {message["path"]: message for topic, message in messages if topic == "/artefacts"}
    assert [hashed[path]["role"] for path in ("sphere_grid.npz", "surface.npz", "symmetry.npz")] == [
        "input",
        "input",
        "output",
    ]
    assert hashed["symmetry.npz"]["sha256"] == file_digest(folder / "symmetry.npz")[0]
    symmetry = artefacts["classify"]
    counts = dict(messages)["/counts"]
    assert counts["reduced_spheres"] == counts["axis"] == len(symmetry)  # a capsule: all on its symmetry axis
    timing = json.loads((folder / "timing.json").read_text())
    assert dict(messages)["/timing"] == timing and 0 < timing["record_seconds"] < timing["seconds"]
    rrd = folder / "logs" / "object.rrd"
    assert instances(rrd, "/capsule-1.0/spheres", "Ellipsoids3D:centers") == len(artefacts["mat"])
    assert instances(rrd, "/capsule-1.0/reduced", "Points3D:positions") == len(symmetry)
    assert instances(rrd, "/capsule-1.0/surface/samples", "Points3D:positions") == len(artefacts["sample"].points)

    # params record: false -> the declared .rrd exists, empty; the log is still written
    assert run_classify_stage(folder, monkeypatch, record=False) == 0
    assert rrd.stat().st_size == 0 and json.loads((folder / "timing.json").read_text())["record_seconds"] == 0
    assert ("/counts", counts) in read_log(folder / "logs" / "classify.mcap")


def test_a_failed_stage_leaves_no_log_recording_or_timing(recorded, monkeypatch, capsys, tmp_path):
    folder, _ = recorded
    for name in ("sphere_grid.npz", "surface.npz"):
        (tmp_path / name).write_bytes((folder / name).read_bytes())
    (tmp_path / "broken.npz").write_bytes(b"PK\x03\x04 not a zip")
    assert run_classify_stage(tmp_path, monkeypatch, record=True, grid="broken.npz") == 2
    assert capsys.readouterr().err.startswith("error: broken.npz")
    left = sorted(path.name for path in tmp_path.rglob("*") if path.is_file())
    assert left == ["broken.npz", "params.yaml", "sphere_grid.npz", "surface.npz"]

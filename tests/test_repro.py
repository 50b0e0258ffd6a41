"""The parallel lanes of ``python -m pipeline.repro``: objects at once, each object's stage files
in DAG order, and the first failure stops new objects (DVC itself replaced by a script)."""

import os
import sys

import pytest

from pipeline import dag, repro


def fake_dvc(tmp_path, monkeypatch):
    """A ``dvc`` that logs (object, start, end) of each lane command and fails on 'broken'."""
    log = tmp_path / "log.txt"
    script = tmp_path / "dvc.py"
    script.write_text(
        "import os, sys, time\n"
        "targets = sys.argv[4:]\n"
        "name, stage = targets[0].split('/')[2], targets[0].split('/')[1]\n"
        "start = time.monotonic()\n"
        "time.sleep(0.4)\n"
        "print('ran', ' '.join(targets))\n"
        "cores = ','.join(map(str, sorted(os.sched_getaffinity(0))))\n"
        f"open({str(log)!r}, 'a').write(f'{{name}} {{start}} {{time.monotonic()}} {{cores}} {{stage}}\\n')\n"
        "sys.exit(1 if name == 'broken' else 0)\n"
    )
    monkeypatch.setattr(repro, "DVC", [sys.executable, str(script)])
    return log


def read_log(log):
    """{object: (start, end, cores)} of the fake dvc's log (its last command per object)."""
    rows = [line.split() for line in log.read_text().splitlines()]
    return {name: (float(start), float(end), cores) for name, start, end, cores, _ in rows}


def read_tasks(log):
    """[(object, first stage, start, end)] of the fake dvc's log, in start order."""
    rows = [line.split() for line in log.read_text().splitlines()]
    return sorted(
        ((name, stage, float(start), float(end)) for name, start, end, _, stage in rows), key=lambda row: row[2]
    )


def test_lanes_run_objects_at_once_each_in_dag_order(tmp_path, monkeypatch, capsys):
    log = fake_dvc(tmp_path, monkeypatch)
    assert repro.lane_targets("duck") == [f"dag/{entry.name}/duck/dvc.yaml" for entry in dag.STAGES]
    assert repro.run_lanes(["a", "b", "c", "d"], jobs=2) == {}
    spans = read_log(log)
    assert sorted(spans) == ["a", "b", "c", "d"]
    # two lanes: the first two objects run at once, and no more than two ever do
    assert spans["a"][0] < spans["b"][1] and spans["b"][0] < spans["a"][1]
    for name, (start, _, _) in spans.items():
        assert sum(other[0] <= start < other[1] for other in spans.values()) <= 2, name
    # each lane keeps to its share of the cores (one each, on two), so the stages do not compete
    machine = os.sched_getaffinity(0)
    shares = {frozenset(map(int, cores.split(","))) for _, _, cores in spans.values()}
    if len(machine) >= 2:  # two disjoint shares that make up the machine
        assert len(shares) == 2 and not frozenset.intersection(*shares) and frozenset.union(*shares) == machine
    else:
        assert shares == {frozenset(machine)}
    out = capsys.readouterr().out.splitlines()
    assert f"[c] ran {' '.join(repro.lane_targets('c'))}" in out


def test_first_failed_lane_stops_new_objects(tmp_path, monkeypatch):
    log = fake_dvc(tmp_path, monkeypatch)
    failed = repro.run_lanes(["broken", "b", "c", "d", "e"], jobs=2)
    assert list(failed) == ["broken"] and failed["broken"][-1].startswith("ran dag/sample/broken/dvc.yaml")
    # the lane beside it finishes its object; nobody starts the remaining ones
    ran = set(read_log(log))
    assert "broken" in ran and "b" in ran and not {"d", "e"} & ran


def test_an_objects_round_starts_after_its_previous_one_and_others_fill_the_lanes(tmp_path, monkeypatch):
    log = fake_dvc(tmp_path, monkeypatch)
    first, second = dag.STAGES[:2], dag.STAGES[2:]
    assert repro.run_lanes(["a", "b", "c"], jobs=2, rounds=(first, second)) == {}
    tasks = read_tasks(log)
    spans = {(name, stage): (start, end) for name, stage, start, end in tasks}
    assert len(tasks) == len(spans) == 6 and {stage for _, stage in spans} == {"sample", "mat"}
    for name in "abc":  # each object's second round only after its first
        assert spans[name, "sample"][1] <= spans[name, "mat"][0]
    # while c's first round runs, the other lane runs a's second: no lane waits for the round
    assert spans["a", "mat"][0] < spans["c", "sample"][1]


def test_the_last_round_takes_the_costliest_object_first_once_its_earlier_rounds_ran(tmp_path, monkeypatch):
    log = fake_dvc(tmp_path, monkeypatch)
    first, second = dag.STAGES[:2], dag.STAGES[2:]
    asked = []

    def cost(name):  # asked only once an object's first round is done, and once per object
        asked.append(name)
        assert any(row[:2] == (name, "sample") for row in read_tasks(log))
        return {"a": 1.0, "b": 3.0, "c": 2.0, "d": 3.0}[name]

    assert repro.run_lanes(["a", "b", "c", "d"], jobs=1, rounds=(first, second), cost=cost) == {}
    order = [(name, stage) for name, stage, _, _ in read_tasks(log)]
    assert order == [(name, "sample") for name in "abcd"] + [(name, "mat") for name in "bdca"]  # ties: queue order
    assert sorted(asked) == ["a", "b", "c", "d"]


def test_check_work_estimates_the_noisy_copies_and_physics_of_each_run(tmp_path):
    import json

    import pandas as pd

    from pipeline.params import Params

    params = Params()
    run = tmp_path / "duck" / str(float(params.scales[0])) / params.candidates.hands[0]
    (run / "timing").mkdir(parents=True)
    outcomes = ["force_closure"] * 10 + ["no_contact"] * 30 + ["no_force_closure"] * 4
    pd.DataFrame({"planner": ["mat"] * 40 + ["baseline"] * 4, "outcome": outcomes}).to_parquet(run / "trials.parquet")
    (run / "timing" / "simulate.json").write_text(json.dumps({"process_seconds": 8.8}))  # 0.2 s a trial
    # mat: 25 of 40 checked, a quarter of them closed; baseline: all 4, all closed
    copies = (25 + 4) * params.checks.robust_samples * 0.2
    expected = copies + (25 * 10 / 40 + 4) * repro.PHYSICS_CHECK_S
    assert repro.check_work("duck", params, data=tmp_path) == pytest.approx(expected)
    assert repro.check_work("absent", params, data=tmp_path) == 0.0


def test_the_checks_are_a_round_of_their_own():
    first, *later = repro.rounds()
    assert (first, sum(later, ())) == repro.phases()
    assert [[entry.name for entry in part] for part in later] == [["simulate", "decompose"], ["check"]]


def test_stages_that_run_trials_wait_for_the_compiled_kernels():
    before, after = repro.phases()
    assert before + after == dag.STAGES
    engine = "pipeline/trial/engine.py"
    assert [entry.name for entry in before if engine in dag.code_deps(entry.name)] == []
    assert after[0].name == "simulate" and engine in dag.code_deps("simulate")
    assert "check" in [entry.name for entry in after]  # its robust copies run trials too
    trials_first = dag.STAGES[[entry.name for entry in dag.STAGES].index("simulate") :]
    assert repro.phases(trials_first) == ((), trials_first)

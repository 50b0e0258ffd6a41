"""The report's tables and metrics against hand-counted trials, and the folder catalogue."""

import numpy as np
import pandas as pd
import pytest
import trimesh
import yaml

from pipeline.errors import BadInputError
from pipeline.geometry.catalogue import folder_entries, replace_objects
from pipeline.outputs import report


def trials_of(outcomes, epsilons, planner, hand="armar3"):
    return pd.DataFrame({"planner": planner, "hand": hand, "outcome": outcomes, "epsilon": epsilons})


@pytest.fixture
def trials():
    # mug x1 armar3: MAT 3 of 4 force closure (eps .12 .22 .32), baseline 1 of 4 (eps .4)
    # mug x0.5 armar3: MAT 0 of 2, baseline 2 of 2 (eps .05 .15); ball x1 armar3: no trials at all
    mug = pd.concat(
        [
            trials_of(["force_closure"] * 3 + ["collision"], [0.12, 0.22, 0.32, 0], "mat"),
            trials_of(["force_closure", "no_contact", "no_contact", "no_force_closure"], [0.4, 0, 0, 0], "baseline"),
        ]
    )
    half = pd.concat(
        [
            trials_of(["no_contact", "error"], [0, 0], "mat"),
            trials_of(["force_closure", "force_closure"], [0.05, 0.15], "baseline"),
        ]
    )
    empty = pd.DataFrame({"planner": [], "hand": [], "outcome": [], "epsilon": []})
    return report.combine({("mug", 1.0, "armar3"): mug, ("mug", 0.5, "armar3"): half, ("ball", 1.0, "armar3"): empty})


RUNS = [("mug", 1.0, "armar3"), ("mug", 0.5, "armar3"), ("ball", 1.0, "armar3")]


def test_results_count_every_run_by_hand(trials):
    table = report.results(trials, RUNS).set_index(["object", "scale", "hand"])
    assert list(table.index) == RUNS
    assert table.loc[RUNS[0], "mat_force_closure_pct"] == 75.0
    assert table.loc[RUNS[0], "baseline_force_closure_pct"] == 25.0
    assert table.loc[RUNS[0], "mat_mean_epsilon"] == pytest.approx(0.22)
    assert table.loc[RUNS[0], "baseline_mean_epsilon"] == pytest.approx(0.4)
    assert table.loc[RUNS[1], "mat_force_closure_pct"] == 0.0 and np.isnan(table.loc[RUNS[1], "mat_mean_epsilon"])
    assert table.loc[RUNS[1], "baseline_mean_epsilon"] == pytest.approx(0.1)
    assert table.loc[RUNS[0], ["force_closure", "collision", "no_contact"]].tolist() == [3, 1, 0]
    assert table.loc[RUNS[1], ["no_contact", "error"]].tolist() == [1, 1]
    assert table.loc[RUNS[2], "mat_trials"] == 0 and np.isnan(table.loc[RUNS[2], "mat_force_closure_pct"])


def test_metrics_overall_per_hand_and_wins(trials):
    metrics = report.metrics(trials, report.results(trials, RUNS))
    for planner in ("mat", "baseline"):
        assert {key: metrics[planner][key] for key in ("force_closure_rate", "trials", "checked")} == {
            "force_closure_rate": 0.5,
            "trials": 6,
            "checked": 0,
        }
        assert np.isnan(metrics[planner]["physics_success_rate"]) and np.isnan(metrics[planner]["robust_fc"])
    assert metrics["per_scale"]["1.0"] == {"mat": 0.75, "baseline": 0.25}
    assert metrics["per_hand"]["armar3"] == {"mat": 0.5, "baseline": 0.5}
    assert (metrics["runs_compared"], metrics["runs_mat_above_baseline"]) == (2, 1)


def test_markdown_has_a_row_per_run_and_names_the_losers(trials):
    table = report.results(trials, RUNS)
    timings = report.timing_table(
        [
            {"stage": "simulate", "seconds": 3.0, "process_seconds": 4.0, "record_seconds": 1.0},
            {"stage": "sample", "seconds": 1.0, "process_seconds": 2.5},
            {"stage": "sample", "seconds": 2.0},
        ]
    )
    assert timings.stage.tolist() == ["sample", "simulate"] and timings.total_s.tolist() == [3.0, 3.0]
    assert timings.process_total_s.tolist() == [4.5, 4.0]  # a record without process time counts its work
    assert timings.record_total_s.tolist() == [0.0, 1.0]
    text = report.markdown(table, report.metrics(trials, table), timings, settings="protocol")
    assert "| mug | 75.0 | 0.0 |" in text  # Table I: ARMAR-III x1, x0.5
    assert "| ball | - |  |" in text  # no candidates: no rate, not 0 %
    assert "| mug | 25.0 | 100.0 |" in text  # the baseline's Table I
    assert "mug x0.5 armar3 (0.0 vs 100.0)" in text
    assert "Recording took 1.0 s of the stages' 8.5 s: it added 13.3 % to the run" in text  # 1 / (8.5 - 1)
    assert "Runs without MAT trials (no sphere of the reduced set fits the hand): ball x1 armar3" in text
    assert sum(line.startswith(("| mug | 1 |", "| mug | 0.5 |", "| ball | 1 |")) for line in text.splitlines()) == 3


def test_plot_tables(trials):
    force_closure, histogram = report.plot_tables(report.results(trials, RUNS), trials, bins=4)
    assert force_closure["mat"].run.tolist() == ["mug x1 armar3", "mug x0.5 armar3", "ball x1 armar3"]
    assert force_closure["mat"].force_closure_pct.tolist() == [75.0, 0.0, 0.0]
    assert force_closure["baseline"].force_closure_pct.tolist() == [25.0, 100.0, 0.0]
    # bins of 0.1 over [0, 0.4]: MAT eps .12 .22 .32, baseline .05 .15 .4
    assert histogram.epsilon.tolist() == pytest.approx([0.05, 0.15, 0.25, 0.35])
    assert histogram.mat.tolist() == [0, 1, 1, 1] and histogram.baseline.tolist() == [1, 1, 0, 1]


def test_folder_entries_and_params_rewrite(tmp_path):
    folder = tmp_path / "off"
    folder.mkdir()
    trimesh.creation.box(extents=[3.0, 4.0, 12.0]).export(folder / "10.off")
    trimesh.creation.box(extents=[1.0, 1.0, 1.0]).export(folder / "2.off")
    (folder / "notes.txt").write_text("not a mesh")
    entries = folder_entries(folder, size=0.26)
    assert list(entries) == ["mesh_2", "mesh_10"]  # natural order, names YAML keeps as strings
    assert entries["mesh_10"]["scale"] == pytest.approx(0.26 / 13.0)  # diagonal of 3 x 4 x 12 is 13
    assert entries["mesh_2"]["source"] == str((folder / "2.off").resolve())
    assert list(folder_entries(folder, scale=0.001, only=["10"], prefix="chen_")) == ["chen_10"]
    with pytest.raises(BadInputError, match="no mesh named 7"):
        folder_entries(folder, only=["7"])
    text = 'seed: 0\n\nobjects:\n  # comment\n  box: {source: "primitive:box"}\n\n# next\nscales: [1.0]\n'
    rewritten = replace_objects(text, entries)
    assert yaml.safe_load(rewritten) == {"seed": 0, "objects": entries, "scales": [1.0]}
    assert "# next\nscales" in rewritten


def test_a_rate_is_printed_from_its_value_not_from_a_rounded_one():
    # held in 180 of 1,300 checks: 13.846 %; a rate rounded to 1e-4 first (0.1385) printed 13.9 %
    planners = [trials_of(["force_closure"] * 1300, [0.1] * 1300, planner) for planner in ("mat", "baseline")]
    trials = report.combine({("cube", 1.0, "armar3"): pd.concat(planners, ignore_index=True)})
    held = np.arange(len(trials)) % 1300 < 180
    for check in ("physics", "mujoco", "mujoco_open"):
        trials[f"{check}_outcome"] = np.where(held, "held", "dropped")
        trials[f"{check}_success"] = held
    metrics = report.metrics(trials, report.results(trials, [("cube", 1.0, "armar3")]))
    assert metrics["baseline"]["physics_success_rate"] == pytest.approx(180 / 1300, abs=1e-6)
    assert "13.8 |" in report.engines_table(metrics) and "13.9" not in report.engines_table(metrics)

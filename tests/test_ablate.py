"""The ablation of the trial's modelling choices (pipeline.checks.ablate, issue 15): the same
candidates with one ``simulate`` setting switched at a time."""

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from pipeline.checks.ablate import ablate, ablation_candidates, variant_params
from pipeline.hands.spec import HANDS
from pipeline.params import Params, SimulateParams
from pipeline.trial.protocol import run_trials
from test_simulation import cube

REPO = Path(__file__).resolve().parents[1]
JAW = HANDS["parallel_jaw"]


def jaw_candidates():
    """16 parallel-jaw candidates on the 4 cm cube: 4 "spheres" (grasp points 0-9 mm off its
    centre), each approached along 4 directions, tilted 0-40 degrees off a face normal."""
    rows = []
    for sphere, offset in enumerate((0.0, 0.003, 0.006, 0.009)):
        for rank, tilt in enumerate(np.radians([0.0, 15.0, 30.0, 40.0])):
            approach = np.array([np.sin(tilt), 0.0, -np.cos(tilt)])
            rows.append(
                {
                    "hand": JAW.name,
                    "id": sphere * 64 + rank,
                    "sphere_index": sphere,
                    "sphere_class": "axis",
                    "diameter_m": 0.04,
                    "preshape": "parallel",
                    **dict(zip(("grasp_x", "grasp_y", "grasp_z"), (offset, -offset, 0.0))),
                    **dict(zip(("approach_x", "approach_y", "approach_z"), approach)),
                    **dict(zip(("orient_x", "orient_y", "orient_z"), (0.0, 1.0, 0.0))),
                }
            )
    return pd.DataFrame(rows)


def small_params(**simulate):
    return Params(simulate=SimulateParams(spheres_per_object=3, **simulate))


def test_the_default_row_is_a_plain_run_of_the_same_candidates_and_mu_1_never_lowers_force_closure():
    candidates = jaw_candidates()
    before = candidates.copy()
    params = small_params()
    table = ablate(cube(), candidates, [JAW], params, physics_trials=0, variants=(("mu", 1.0),))
    pd.testing.assert_frame_equal(candidates, before)  # the input is not modified
    assert list(table.setting) == ["params", "params", "mu=1", "mu=1"]
    assert list(table.planner) == ["mat", "baseline"] * 2
    # the simulate stage's choice: 3 of the 4 spheres (12 candidates), as many baseline trials
    mat, baseline = ablation_candidates(cube(), candidates, JAW, params.simulate, seed=0)
    assert len(mat) == 12 == len(baseline) and (table.trials == 12).all()
    plain = run_trials(cube(), [JAW], [(0, mat), (0, baseline)], params.simulate)
    for planner, results in zip(("mat", "baseline"), plain):
        row = table[(table.variant == "default") & (table.planner == planner)].iloc[0]
        closed = 100.0 * np.mean([result.outcome == "force_closure" for result in results])
        assert row.force_closure_pct == closed and row.force_closure_delta == 0.0
        assert np.isnan(row.physics_success_pct) and row.physics_checked == 0
    # force closure is monotone in mu on the same closed hands (wider cones, same contacts)
    default, wider = (table[table.variant == name].set_index("planner") for name in ("default", "mu"))
    assert (wider.force_closure_pct >= default.force_closure_pct).all()
    assert (wider.force_closure_delta == wider.force_closure_pct - default.force_closure_pct).all()
    assert table[table.variant == "default"].force_closure_pct.max() > 0


def test_the_ablation_on_two_workers_gives_the_table_of_one_process():
    params, variants = small_params(), (("mu", 1.0), ("approach_to_contact", False))
    one = ablate(cube(), jaw_candidates(), [JAW], params, physics_trials=0, variants=variants)
    two = ablate(cube(), jaw_candidates(), [JAW], params, physics_trials=0, variants=variants, workers=2)
    assert len(one) == 6 and one.force_closure_pct.max() > 0
    pd.testing.assert_frame_equal(one, two)


def test_variants_keep_the_params_valid_and_a_repeated_variant_runs_once():
    base = SimulateParams()
    wide = variant_params(base, "contact_tolerance_m", 0.004)
    assert (wide.near_m, wide.approach_step_m) == (0.004, 0.001)
    narrow = variant_params(base, "contact_tolerance_m", 0.001)
    assert (narrow.near_m, narrow.approach_step_m) == (0.004, 0.001)
    # an approach step longer than the tolerance is cut to it (a step must not jump past a touch)
    fine = dataclasses.replace(base, approach_step_m=0.0005, contact_tolerance_m=0.0015)
    assert variant_params(fine, "approach_step_m", 0.002).approach_step_m == 0.0015
    table = ablate(
        cube(),
        jaw_candidates(),
        [JAW],
        small_params(),
        cap=5,
        physics_trials=0,
        variants=(("mu", 0.5), ("palm_contacts", False), ("palm_contacts", False)),
    )
    assert list(table.variant) == ["default", "default", "palm_contacts", "palm_contacts"]
    assert (table.trials == 5).all()  # the seeded cap


def test_an_object_without_candidates_gives_an_empty_table_with_the_columns():
    from pipeline.checks.ablate import COLUMNS

    empty = jaw_candidates().iloc[:0]
    table = ablate(cube(), empty, [JAW], small_params(), physics_trials=0)
    assert len(table) == 0 and list(table.columns) == list(COLUMNS)


def test_physics_success_counts_only_closed_hands_and_checks_each_closed_hand_once():
    table = ablate(
        cube(), jaw_candidates(), [JAW], small_params(), cap=4, physics_trials=2, variants=(("coplanar_deg", 15.0),)
    )
    assert (table.physics_checked <= 2).all() and (table.physics_held <= table.physics_checked).all()
    assert table.physics_checked.sum() > 0 and table.physics_held.sum() > 0
    for row in table.itertuples():
        if row.physics_checked:
            expected = row.closed_pct * row.physics_held / row.physics_checked
            assert row.physics_success_pct == pytest.approx(expected)
    # coplanar_deg only regroups the contacts: the same closed hands, the same physics verdicts
    default, regrouped = (table[table.variant == name].set_index("planner") for name in ("default", "coplanar_deg"))
    assert (default.physics_held == regrouped.physics_held).all()


def test_the_command_prints_the_table_and_writes_the_csv(tmp_path, capsys):
    from pipeline.__main__ import main
    from pipeline.artefacts import write_table

    folder = tmp_path / "run"
    cube().save(folder / "surface.npz")
    write_table(folder / JAW.name / "candidates.parquet", jaw_candidates())
    out = tmp_path / "ablation.csv"
    main(["ablate", "--from-data", str(folder), "--hand", JAW.name, "--spheres", "2",
          "--physics-trials", "0", "--workers", "1", "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out
    assert "approach_to_contact=false" in printed and "contact_tolerance_m=0.004" in printed and "fc %" in printed
    written = pd.read_csv(out)
    assert len(written) == 2 * 14 and set(written.planner) == {"mat", "baseline"}
    assert {"variant", "setting", "force_closure_pct", "force_closure_delta", "physics_success_pct"} <= set(
        written.columns
    )
    assert (written.trials == 8).all()


@pytest.mark.parametrize(
    "arguments, problem",
    [
        (["primitive:box", "--hand", "shadow"], "shadow"),
        ([], "give a MESH or --from-data DIR"),
        (["--from-data", "nowhere", "--hand", "parallel_jaw"], "nowhere/surface.npz: missing"),
    ],
)
def test_bad_input_is_one_line_and_exit_code_2(arguments, problem):
    result = subprocess.run(
        [sys.executable, "-m", "pipeline", "ablate", *arguments],
        capture_output=True,
        text=True,
        cwd=REPO,
        env={**os.environ, "PYTHONPATH": str(REPO)},
    )
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and problem in lines[0], result.stderr


def test_help_has_a_description_and_an_example(capsys):
    from pipeline.__main__ import main

    with pytest.raises(SystemExit) as exited:
        main(["ablate", "--help"])
    text = capsys.readouterr().out
    assert exited.value.code == 0
    assert text.split("example:\n", 1)[1].splitlines()[0].strip().startswith("python -m pipeline ablate ")
    assert "retreat only" in " ".join(text.split())


def test_class_means_average_the_runs_of_a_class_and_skip_objects_without_trials():
    from pipeline.checks.ablate import COLUMNS, class_markdown, class_means

    def table(hand, default, switched):
        rows = []
        for variant, setting, rate in (("default", "params", default), ("mu", "mu=1", switched)):
            rows.append({"hand": hand, "variant": variant, "setting": setting, "planner": "mat", "trials": 10,
                         "force_closure_pct": rate, "physics_success_pct": rate / 2,
                         "force_closure_delta": rate - default, "physics_success_delta": (rate - default) / 2})  # fmt: skip
        return pd.DataFrame(rows).reindex(columns=list(COLUMNS))

    tables = {"a": table("armar3", 20.0, 30.0), "b": table("barrett", 40.0, 70.0), "c": table("armar3", 0, 0).iloc[:0]}
    means = class_means(tables, {"pair": ("a", "b", "c")})
    switched = means[means.variant == "mu"].iloc[0]
    assert (switched.runs, switched.trials) == (2, 20)
    assert (switched.force_closure_pct, switched.force_closure_delta, switched.physics_success_delta) == (50, 20, 10)
    text = class_markdown(means, {"pair": ("a", "b", "c")})
    assert "**pair** (a, b, c; 2 runs)" in text and "| default (% of trials) | 30.0 | 15.0 | - | - |" in text
    assert "| `mu=1` | +20.0 | +10.0 | - | - |" in text

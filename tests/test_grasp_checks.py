"""The checks of a run's trials (pipeline.checks.protocol, stage ``check``): which trials are
checked, what an unclosed trial gets, and that the results depend on the seed alone."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from pipeline.checks.physics import decompose
from pipeline.checks.protocol import check_trials, empty_checks, summary, with_checks
from pipeline.errors import ArtefactError
from pipeline.hands.spec import HANDS
from pipeline.params import CheckParams, SimulateParams
from pipeline.trial.protocol import baseline_candidates, simulate
from test_simulation import cube

JAW = HANDS["parallel_jaw"]


@pytest.fixture(scope="module")
def run():
    """The jaw on a 4 cm cube: 12 'MAT' candidates (surface-normal ones, one per sphere) and 12
    baseline trials, some closing on the cube, some not; the cube's convex parts."""
    surface = cube()
    candidates = baseline_candidates(surface, JAW, 12, np.random.default_rng(3)).assign(sphere_index=np.arange(12))
    trials, _ = simulate(surface, candidates, [JAW], spheres_per_object=12, baseline_trials=12, seed=0)
    return surface, trials, decompose(surface)


def checked(run, workers=1, **checks):
    surface, trials, parts = run
    settings = SimulateParams()
    keywords = {**dataclasses.asdict(CheckParams()), "trials": 5, "robust_samples": 3, **checks}
    return check_trials(surface, trials, parts, hands=[JAW], seed=7, settings=settings, workers=workers, **keywords)


def test_a_seeded_sample_per_planner_with_physics_only_on_closed_hands(run):
    _, trials, _ = run
    table = checked(run)
    assert table.groupby("planner").size().to_dict() == {"baseline": 5, "mat": 5}
    for planner, rows in table.groupby("planner"):
        assert (trials.planner.iloc[rows.trial] == planner).all() and rows.trial.is_monotonic_increasing
    assert (table.outcome.to_numpy() == trials.outcome.astype(str).iloc[table.trial].to_numpy()).all()
    closed = table.outcome.isin(["force_closure", "no_force_closure"])
    assert closed.any() and (~closed).any()  # the fixture has both kinds in its sample
    for check in ("physics", "mujoco", "mujoco_open"):  # checks.engine both: pybullet and MuJoCo's two starts
        outcome = table[f"{check}_outcome"]
        assert (outcome[~closed] == "no_grasp").all() and table[f"{check}_slip_m"][~closed].isna().all()
        assert outcome[closed].isin(["held", "slipped", "dropped", "no_grasp"]).all()
        assert (table[f"{check}_success"] == (outcome == "held")).all()
        # a force-closure jaw grasp across two faces of the cube holds
        assert (outcome[table.outcome == "force_closure"] == "held").any()
    assert table.robust_fc.isin([0.0, 1 / 3, 2 / 3, 1.0]).all()  # 3 copies each
    np.testing.assert_allclose(table.mass_kg, 0.032, rtol=1e-9)  # 64 cm^3 at 500 kg/m^3, under the 0.1 kg payload


@pytest.mark.parametrize("engine", ["pybullet", "mujoco"])
def test_checks_engine_runs_that_engine_alone(run, engine):
    table = checked(run, engine=engine)
    ran = {"pybullet": ["physics"], "mujoco": ["mujoco", "mujoco_open"]}[engine]
    for check in ("physics", "mujoco", "mujoco_open"):
        assert (table[f"{check}_outcome"] != "").all() == (check in ran)
        assert (table[f"{check}_outcome"] == "").all() == (check not in ran)
    assert np.isnan(summary(table)["mat"]["engines_agree"])


def test_a_heavy_object_is_checked_at_the_payload_not_counted_as_a_failed_grasp(run):
    """The same cube at 200,000 kg/m^3 weighs 12.8 kg: no cap, the jaw's 2 x 20 N grip (friction
    20 N) drops it from every force-closure grasp, on both engines. Under the graspable-mass
    rule (payload 0.1 kg) it is checked at 0.1 kg, and the force-closure grasps hold it about as
    often as the 32 g cube (measured: pybullet 4 and 2 of 9, MuJoCo 4 and 4, its open start 4 and 4)."""
    light = checked(run)
    heavy = checked(run, density_kg_m3=200000.0, payload_kg=-1.0)
    capped = checked(run, density_kg_m3=200000.0)
    assert heavy.mass_kg.iloc[0] == pytest.approx(12.8) and (capped.mass_kg == 0.1).all()
    force_closure = light.outcome == "force_closure"
    for check in ("physics", "mujoco", "mujoco_open"):
        assert light[f"{check}_success"][force_closure].any()
        assert not heavy[f"{check}_success"].any()
        held, held_capped = (
            light[f"{check}_success"][force_closure].sum(),
            capped[f"{check}_success"][force_closure].sum(),
        )
        assert held_capped >= max(1, held / 2)  # marginal grasps (slip near 2 cm) go either way


def test_the_same_seed_gives_the_same_table_whatever_the_workers(run):
    pd.testing.assert_frame_equal(checked(run), checked(run, workers=2))
    other = checked(run, trials=-1, physics=False)
    assert len(other) == len(run[1])  # -1: every trial
    # a trial's noisy copies come from its own seed: the same in a larger sample
    both = checked(run).merge(other, on="trial", suffixes=("", "_all"))
    assert len(both) == 10 and (both.robust_fc == both.robust_fc_all).all()
    assert (other.physics_outcome == "").all() and not other.physics_success.any()


def test_no_checks_is_an_empty_table_with_the_columns(run):
    table = checked(run, trials=0)
    assert len(table) == 0 and list(table.columns) == list(empty_checks().columns)
    assert np.isnan(summary(table)["mat"]["physics_success_rate"])


def test_summary_counts_the_checked_trials(run):
    table = checked(run)
    result = summary(table)
    mat = table[table.planner == "mat"]
    assert result["mat"]["checked"] == 5
    assert result["mat"]["physics_success_rate"] == pytest.approx(mat.physics_success.mean())
    assert result["mat"]["robust_fc"] == pytest.approx(mat.robust_fc.mean())
    assert sum(result["mat"]["physics_outcomes"].values()) == 5
    assert result["mat"]["mujoco_open_success_rate"] == pytest.approx(mat.mujoco_open_success.mean())
    agree = (mat.physics_success == mat.mujoco_success).mean()
    assert result["mat"]["engines_agree"] == pytest.approx(agree)


def test_a_checks_table_of_other_trials_is_refused(run):
    _, trials, _ = run
    table = checked(run)
    with pytest.raises(ArtefactError, match="not those of the trials table"):
        with_checks(trials.iloc[: table.trial.max()], table)  # its last checked trial is gone
    shuffled = trials.assign(planner=trials.planner.map({"mat": "baseline", "baseline": "mat"}))
    with pytest.raises(ArtefactError):
        with_checks(shuffled, table)


def test_the_report_counts_robust_only_checks(run):
    """With the physics check off, the report still counts the checked trials and shows their
    robust force closure (no physics success)."""
    from pipeline.outputs import report

    _, trials, _ = run
    key = ("cube", 1.0, "parallel_jaw")
    combined = report.combine({key: trials}, {key: checked(run, physics=False)})
    metrics = report.metrics(combined, report.results(combined, [key]))
    assert metrics["mat"]["checked"] == 5 and 0 <= metrics["mat"]["robust_fc"] <= 1
    assert np.isnan(metrics["mat"]["physics_success_rate"])


def test_the_report_shows_each_engine_and_their_agreement(run):
    """From the checks of both engines, hand-counted: the run's held % per check and the engines'
    agreement % in the results, Table I's cells (force closure (pybullet / MuJoCo / robust)),
    the engines table, and a calibration table and plot columns per check."""
    from pipeline.outputs import report

    _, trials, _ = run
    key = ("cube", 1.0, "parallel_jaw")
    table = checked(run)
    combined = report.combine({key: trials}, {key: table})
    results = report.results(combined, [key])
    mat = table[table.planner == "mat"]
    row = results.iloc[0]
    for check in ("physics", "mujoco", "mujoco_open"):
        assert row[f"mat_{check}_success_pct"] == pytest.approx(100 * mat[f"{check}_success"].mean())
    agree = 100 * (mat.physics_success == mat.mujoco_success).mean()
    assert row.mat_engines_agree_pct == pytest.approx(agree)
    cell = report.table_one(results, "mat").splitlines()[-1]
    expected = [row.mat_physics_success_pct, row.mat_mujoco_success_pct, row.mat_robust_fc_pct]
    assert f"({' / '.join(f'{value:.1f}' for value in expected)})" in cell
    metrics = report.metrics(combined, results)
    engines = report.engines_table(metrics).splitlines()
    assert engines[2].startswith("| parallel jaw | mat |") and engines[2].endswith(f"| {agree:.1f} |")
    calibration = report.calibration(combined)
    assert list(calibration.check.unique()) == ["physics", "mujoco", "mujoco_open"]
    for check in ("physics", "mujoco", "mujoco_open"):
        rows = calibration[(calibration.check == check) & (calibration.score == "robust_fc")]
        assert rows.checked.sum() == (combined[f"{check}_outcome"] != "").sum()
    plots = report.calibration_plots(calibration)
    assert {"mat", "baseline", "mat_mujoco", "baseline_mujoco_open", "mat_mujoco_open_checked"} <= set(plots["epsilon"])


def test_without_the_physics_checks_decompose_runs_no_v_hacd_and_the_checks_need_no_parts(run, tmp_path):
    surface, trials, parts = run
    assert len(parts.parts) >= 1 and len(parts.vertices) >= 8  # V-HACD's hull of the cube
    none = decompose(surface, physics=False)
    assert none.parts == [] and none.vertices.shape == (0, 3) and none.key != parts.key
    none.save(tmp_path / "parts.npz")
    empty = type(parts).load(tmp_path / "parts.npz")
    assert empty.parts == [] and empty.key == none.key
    # robust force closure alone needs no parts: the same as with them
    pd.testing.assert_frame_equal(checked((surface, trials, empty), physics=False), checked(run, physics=False))
    with pytest.raises(ArtefactError, match="convex parts are empty"):
        checked((surface, trials, empty))

"""The checks of a run's trials (pipeline.grasp_checks, stage ``check``): which trials are
checked, what an unclosed trial gets, and that the results depend on the seed alone."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from pipeline.errors import ArtefactError
from pipeline.grasp_checks import check_trials, empty_checks, summary, with_checks
from pipeline.hands import HANDS
from pipeline.params import CheckParams, SimulateParams
from pipeline.physics import decompose
from pipeline.trials import baseline_candidates, simulate
from test_simulation import cube

JAW = HANDS["parallel_jaw"]


@pytest.fixture(scope="module")
def run():
    """The jaw on a 4 cm cube: 12 'MAT' candidates (surface-normal ones, one per sphere) and 12
    baseline trials, some closing on the cube, some not; the cube's convex parts."""
    surface = cube()
    candidates = baseline_candidates(surface, JAW, 12, seed=3).assign(sphere_index=np.arange(12))
    trials, _ = simulate(surface, candidates, [JAW], spheres_per_object=12, baseline_trials=12, seed=0)
    return surface, trials, decompose(surface)


def checked(run, workers=1, **checks):
    surface, trials, parts = run
    settings = SimulateParams().world_settings()
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
    assert (table.physics_outcome[~closed] == "no_grasp").all() and table.physics_slip_m[~closed].isna().all()
    assert table.physics_outcome[closed].isin(["held", "slipped", "dropped", "no_grasp"]).all()
    assert (table.physics_success == (table.physics_outcome == "held")).all()
    assert table.robust_fc.isin([0.0, 1 / 3, 2 / 3, 1.0]).all()  # 3 copies each
    # a force-closure jaw grasp across two faces of the cube holds
    assert (table.physics_outcome[table.outcome == "force_closure"] == "held").any()


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
    from pipeline import report

    _, trials, _ = run
    key = ("cube", 1.0, "parallel_jaw")
    combined = report.combine({key: trials}, {key: checked(run, physics=False)})
    metrics = report.metrics(combined, report.results(combined, [key]))
    assert metrics["mat"]["checked"] == 5 and 0 <= metrics["mat"]["robust_fc"] <= 1
    assert np.isnan(metrics["mat"]["physics_success_rate"])

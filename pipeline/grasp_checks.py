"""The checks of a run's trials (stage ``check``, issue 15): does the analytic score predict
holding?

For a seeded sample of each hand's trials per planner (``checks.trials``; -1 = every trial):

- the physics check (:class:`pipeline.physics.PhysicsCheck`) of every sampled trial that ended
  with a closed hand on the object (outcome ``force_closure`` or ``no_force_closure``); the
  others (``no_contact``, ``collision``, ``step_cap``, ``error``) closed on nothing and are
  ``no_grasp`` without a simulation; a check pybullet refuses is ``error``;
- robust force closure (:mod:`pipeline.robust`) of every sampled trial: ``robust_samples`` noisy
  copies of its candidate through the same trial engine (worker processes as the trials),
  each graded at its own friction.

Seeds: per hand and planner, ``SeedSequence([seed, crc32(hand), planner])`` spawns the sample's
seed and one seed per trial (by its position in that hand's and planner's trials), so a trial's
copies depend neither on the other hands run with it nor on the workers or the sample size.

Table (``checks.parquet``): one row per checked trial; ``trial`` (its row in trials.parquet),
``planner``, ``hand``, ``outcome`` (the trial's), ``epsilon`` (the trial's),
``physics_outcome`` (held, slipped, dropped, no_grasp, error; "" when the physics check is
off), ``physics_success`` (held), ``physics_slip_m`` and ``physics_turn_rad`` (how far the
object moved and turned relative to the hand; NaN without a simulation), ``robust_fc``
(fraction of the copies in force closure) and ``robust_epsilon`` (their mean epsilon; NaN
with ``robust_samples`` 0).
"""

import zlib

import numpy as np
import pandas as pd

from .arrays import vectors
from .errors import ArtefactError
from .robust import perturbed_candidates, robust_scores
from .trials import PLANNERS

#: the checks table's columns that :func:`with_checks` puts on the trials
CHECK_COLUMNS = (
    "physics_outcome",
    "physics_success",
    "physics_slip_m",
    "physics_turn_rad",
    "robust_fc",
    "robust_epsilon",
)
PHYSICS_OUTCOMES = ("held", "slipped", "dropped", "no_grasp", "error")
CLOSED = ("force_closure", "no_force_closure")  # trials that end with a closed hand on the object


def group_seeds(seed, hand_name, planner, count):
    """(sample seed, list of ``count`` per-trial seeds) of one hand's and planner's trials."""
    group = np.random.SeedSequence([seed, zlib.crc32(hand_name.encode()), PLANNERS.index(planner)])
    sample, trials = group.spawn(2)
    return sample, trials.spawn(count)


def sampled(rows, count, sample_seed):
    """The sorted sample of ``count`` of ``rows`` (all of them for -1 or fewer rows)."""
    if count < 0 or len(rows) <= count:
        return np.asarray(rows)
    return np.sort(np.random.default_rng(sample_seed).choice(rows, count, replace=False))


def empty_checks():
    """A checks table with no rows and the columns' types."""
    return pd.DataFrame(
        {
            "trial": pd.Series(dtype=np.int64),
            "planner": pd.Series(dtype=str),
            "hand": pd.Series(dtype=str),
            "outcome": pd.Series(dtype=str),
            "epsilon": pd.Series(dtype=float),
            "physics_outcome": pd.Series(dtype=str),
            "physics_success": pd.Series(dtype=bool),
            **{name: pd.Series(dtype=float) for name in ("physics_slip_m", "physics_turn_rad")},
            **{name: pd.Series(dtype=float) for name in ("robust_fc", "robust_epsilon")},
        }
    )


def check_trials(surface, trial_table, parts, *, hands, seed, settings, workers=1, progress=None, **checks):
    """The checks table (see the module docstring) of ``trial_table``.

    Parameters
    ----------
    surface : SurfaceSamples
    trial_table : pandas.DataFrame
        The trials table (:mod:`pipeline.trials`) of ``hands``.
    parts : pipeline.physics.ConvexParts
    hands : list of Hand
    seed : int
    settings : dict
        The trials' :class:`pipeline.simulation.GraspEngine` keywords (``simulate`` params).
    workers : int
        Processes for the noisy copies' trials; results do not depend on it.
    progress : callable(int, int), optional
        Called with the checks (physics checks and noisy trials) just done and the total.
    **checks
        The ``checks`` params (:class:`pipeline.params.CheckParams`; defaults for those left out).
    """
    from .params import CheckParams
    from .physics import PhysicsSettings
    from .simulation import TrialSettings, torque_reference
    from .trials import run_trials

    params = CheckParams(**checks)
    trials, physics, robust_samples = trial_table, params.physics, params.robust_samples

    picked = []  # (hand number, planner, rows of trials, their seeds)
    for number, hand in enumerate(hands):
        for planner in PLANNERS:
            rows = np.flatnonzero(((trials.hand == hand.name) & (trials.planner == planner)).to_numpy())
            if not len(rows) or params.trials == 0:
                continue
            sample_seed, trial_seeds = group_seeds(seed, hand.name, planner, len(rows))
            chosen = sampled(np.arange(len(rows)), params.trials, sample_seed)
            picked.append((number, planner, rows[chosen], [trial_seeds[k] for k in chosen]))
    if not picked:
        return empty_checks()
    total = sum(len(rows) for _, _, rows, _ in picked) * (int(physics) + robust_samples)
    trial_settings = TrialSettings(**settings)
    physics_settings = PhysicsSettings(**params.physics_settings(trial_settings.mu))
    step = (lambda done, _: progress(done, total)) if progress else None
    robust = {}
    if robust_samples:
        tables, copies = [], []
        for number, planner, rows, seeds in picked:
            table = trials.iloc[rows]
            grasp, approach, orient, mus = perturbed_candidates(
                vectors(table, "grasp"),
                vectors(table, "approach"),
                vectors(table, "orient"),
                seeds,
                samples=robust_samples,
                pose_sigma_m=params.pose_sigma_m,
                angle_sigma_rad=params.angle_sigma_rad,
                mu=trial_settings.mu,
                mu_sigma=params.mu_sigma,
            )
            columns = {
                f"{name}_{axis}": value[:, k]
                for name, value in zip(("grasp", "approach", "orient"), (grasp, approach, orient))
                for k, axis in enumerate("xyz")
            }
            tables.append(
                (number, pd.DataFrame({**columns, "preshape": np.repeat(table.preshape.to_numpy(), robust_samples)}))
            )
            copies.append((rows, mus))
        results = run_trials(surface, hands, tables, settings, workers=workers, progress=step)
        centre, torque_scale = torque_reference(surface.vertices, surface.faces)
        for (rows, mus), result in zip(copies, results):
            scores = robust_scores(
                result,
                mus,
                robust_samples,
                cone_edges=trial_settings.cone_edges,
                torque_scale=torque_scale,
                torsional_friction=trial_settings.torsional_friction_m,
                centre=centre,
            )
            robust.update({row: (fc, eps) for row, fc, eps in zip(rows, *scores)})
    frames = []
    for number, planner, rows, _ in picked:
        table = trials.iloc[rows]
        frame = pd.DataFrame(
            {
                "trial": rows.astype(np.int64),
                "planner": planner,
                "hand": hands[number].name,
                "outcome": table.outcome.astype(str).to_numpy(),
                "epsilon": table.epsilon.to_numpy(float),
            }
        )
        if physics:
            outcomes = _physics(surface, parts, hands[number], table, physics_settings, trial_settings, step)
        else:
            outcomes = [("", np.nan, np.nan)] * len(rows)
        frame["physics_outcome"] = [outcome for outcome, _, _ in outcomes]
        frame["physics_success"] = frame.physics_outcome == "held"
        frame["physics_slip_m"] = np.array([slip for _, slip, _ in outcomes], float)
        frame["physics_turn_rad"] = np.array([turn for _, _, turn in outcomes], float)
        frame["robust_fc"] = [robust.get(row, (np.nan, np.nan))[0] for row in rows]
        frame["robust_epsilon"] = [robust.get(row, (np.nan, np.nan))[1] for row in rows]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _physics(surface, parts, hand, table, physics_settings, trial_settings, progress):
    """(outcome, slip, turn) of each trial of ``table`` (one hand)."""
    from .bullet import pybullet
    from .kinematics import hand_model
    from .physics import PhysicsCheck

    closed = table.outcome.astype(str).isin(CLOSED).to_numpy()
    outcomes = [("no_grasp", np.nan, np.nan)] * len(table)
    if not closed.any():
        if progress:
            progress(len(table), None)
        return outcomes
    model = hand_model(hand, spacing=trial_settings.link_point_spacing_m)
    try:
        check = PhysicsCheck(surface.vertices, surface.faces, hand, model, parts=parts.parts, settings=physics_settings)
    except pybullet.error:  # the object or the hand could not be built: every check of it fails
        outcomes = [("error", np.nan, np.nan) if closed[k] else outcome for k, outcome in enumerate(outcomes)]
        check = None
    try:
        base, quaternion = vectors(table, "base"), table[[f"base_q{axis}" for axis in "xyzw"]].to_numpy(float)
        for k in np.flatnonzero(closed) if check else ():
            try:
                result = check.check(base[k], quaternion[k], np.asarray(table.joints.iloc[k], float))
                outcomes[k] = (result.outcome, result.slip_m, result.turn_rad)
            except pybullet.error:
                outcomes[k] = ("error", np.nan, np.nan)
    finally:
        if check:
            check.close()
    if progress:
        progress(len(table), None)
    return outcomes


def summarise_checks(checks):
    """``checked``, ``physics_success_rate`` (held of the checked trials; NaN if none or the
    physics check was off), ``robust_fc`` (mean) and ``physics_outcomes`` counts of a checks
    table (or a slice of it)."""
    ran = checks[checks.physics_outcome != ""]
    return {
        "checked": int(len(checks)),
        "physics_success_rate": float(ran.physics_success.mean()) if len(ran) else float("nan"),
        "robust_fc": float(checks.robust_fc.mean()) if checks.robust_fc.notna().any() else float("nan"),
        "physics_outcomes": {outcome: int((ran.physics_outcome == outcome).sum()) for outcome in PHYSICS_OUTCOMES},
    }


def summary(checks):
    """The JSON-ready checks of a run: per planner (``mat``, ``baseline``, ``encompassing``) and per hand."""
    return {
        **{planner: summarise_checks(checks[checks.planner == planner]) for planner in PLANNERS},
        "per_hand": {
            hand: {
                planner: summarise_checks(checks[(checks.hand == hand) & (checks.planner == planner)])
                for planner in PLANNERS
            }
            for hand in sorted(checks.hand.unique())
        },
    }


def with_checks(trials, checks):
    """``trials`` (a copy) with the :data:`CHECK_COLUMNS` of ``checks`` (a checks table of the
    same trials, or None) on the checked rows: an unchecked trial has ``physics_outcome`` ""
    and missing values (``physics_success`` is a nullable boolean)."""
    frame = trials.copy()
    checked = checks.set_index("trial") if checks is not None else empty_checks().set_index("trial")
    rows = checked.index.to_numpy()
    if len(rows) and (
        rows.max() >= len(frame)
        or (frame.planner.to_numpy()[rows] != checked.planner.to_numpy()).any()
        or (frame.outcome.astype(str).to_numpy()[rows] != checked.outcome.to_numpy()).any()
    ):
        raise ArtefactError("checks table: its trials are not those of the trials table (stale? rerun its check stage)")
    for column in CHECK_COLUMNS:
        frame[column] = checked[column].reindex(np.arange(len(frame))).to_numpy()
    frame["physics_outcome"] = frame.physics_outcome.astype(object).fillna("").astype(str)
    frame["physics_success"] = frame.physics_success.astype("boolean").where(frame.physics_outcome != "")
    return frame

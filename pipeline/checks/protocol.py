"""The checks of a run's trials (stage ``check``): does the analytic score predict
holding?

For a seeded sample of each hand's trials per planner (``checks.trials``; -1 = every trial):

- the lift-and-shake of ``checks.engine`` (pybullet's :class:`pipeline.checks.physics.PhysicsCheck`,
  MuJoCo's :class:`pipeline.checks.mujoco_check.MujocoCheck` from the closed pose and from the open
  hand, or both) of every sampled trial that ended with a closed hand on the object (outcome
  ``force_closure`` or ``no_force_closure``); the others (``no_contact``, ``collision``,
  ``step_cap``, ``error``) closed on nothing and are ``no_grasp`` without a simulation; a check
  the engine refuses is ``error``;
- robust force closure (:mod:`pipeline.checks.robust`) of every sampled trial: ``robust_samples`` noisy
  copies of its candidate through the same trial engine (worker processes as the trials),
  each graded at its own friction.

Seeds: per hand and planner, :func:`pipeline.seeds.check_group` gives the sample's seed and
one seed per trial (by its position in that hand's and planner's trials), so a trial's
copies depend neither on the other hands run with it nor on the workers or the sample size.

Table (``checks.parquet``): one row per checked trial; ``trial`` (its row in trials.parquet),
``planner``, ``hand``, ``outcome`` (the trial's), ``epsilon`` (the trial's),
per check (:data:`PHYSICS_CHECKS`: ``physics`` pybullet's, ``mujoco`` MuJoCo's from the
closed pose, ``mujoco_open`` MuJoCo's from the open hand) ``<check>_outcome`` (held, slipped,
dropped, no_grasp, error; "" when that check did not run), ``<check>_success`` (held),
``<check>_slip_m`` and ``<check>_turn_rad`` (how far the object moved and turned relative to the
hand; NaN without a simulation); ``mass_kg`` (the checked object's, :func:`pipeline.checks.physics.object_mass`),
``robust_fc`` (fraction of the copies in force closure) and ``robust_epsilon`` (their mean
epsilon; NaN with ``robust_samples`` 0).
"""

import numpy as np
import pandas as pd

from .. import seeds
from ..arrays import vectors
from ..errors import ArtefactError, DegenerateGeometryError
from ..trial.engine import CLOSED
from ..trial.protocol import PLANNERS
from .robust import perturbed_candidates, robust_summary

#: the lift-and-shake checks (column prefixes) and the ``checks.engine`` that runs each
PHYSICS_CHECKS = {"physics": "pybullet", "mujoco": "mujoco", "mujoco_open": "mujoco"}
#: the checks table's columns that :func:`with_checks` puts on the trials
CHECK_COLUMNS = tuple(
    f"{check}_{column}" for check in PHYSICS_CHECKS for column in ("outcome", "success", "slip_m", "turn_rad")
) + ("robust_fc", "robust_epsilon")
PHYSICS_OUTCOMES = ("held", "slipped", "dropped", "no_grasp", "error")


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
            **{
                f"{check}_{column}": pd.Series(dtype=kind)
                for check in PHYSICS_CHECKS
                for column, kind in (("outcome", str), ("success", bool), ("slip_m", float), ("turn_rad", float))
            },
            **{name: pd.Series(dtype=float) for name in ("mass_kg", "robust_fc", "robust_epsilon")},
        }
    )


def check_trials(surface, trial_table, parts, *, hands, seed, settings, workers=1, progress=None, **checks):
    """The checks table (see the module docstring) of ``trial_table``.

    Parameters
    ----------
    surface : SurfaceSamples
    trial_table : pandas.DataFrame
        The trials table (:mod:`pipeline.trial.protocol`) of ``hands``.
    parts : pipeline.checks.physics.ConvexParts
    hands : list of Hand
    seed : int
    settings : SimulateParams
        How the trials ran (the ``simulate`` params).
    workers : int
        Processes for the noisy copies' trials; results do not depend on it.
    progress : callable(int, int), optional
        Called with the checks (physics checks and noisy trials) just done and the total.
    **checks
        The ``checks`` params (:class:`pipeline.params.CheckParams`; defaults for those left out).
    """
    from ..params import CheckParams
    from ..trial.protocol import run_trials
    from .mujoco_check import MujocoSettings
    from .physics import PhysicsSettings, object_mass

    params = CheckParams(**checks)
    trials, physics, robust_samples = trial_table, params.physics, params.robust_samples

    picked = []  # (hand number, planner, rows of trials, their seeds)
    for number, hand in enumerate(hands):
        for planner in PLANNERS:
            rows = np.flatnonzero(((trials.hand == hand.name) & (trials.planner == planner)).to_numpy())
            if not len(rows) or params.trials == 0:
                continue
            sample_seed, trial_seeds = seeds.check_group(seed, hand.name, PLANNERS.index(planner), len(rows))
            chosen = sampled(np.arange(len(rows)), params.trials, sample_seed)
            picked.append((number, planner, rows[chosen], [trial_seeds[k] for k in chosen]))
    if not picked:
        return empty_checks()
    engines = [engine for engine in ("pybullet", "mujoco") if physics and params.engine in (engine, "both")]
    if engines and len(parts.part_start) < 2:
        raise ArtefactError(
            "the convex parts are empty (decompose ran with checks.physics false): `dvc repro` reruns decompose"
        )
    total = sum(len(rows) for _, _, rows, _ in picked) * (len(engines) + robust_samples)
    physics_settings = PhysicsSettings(**params.physics_settings(settings.mu))
    mujoco_settings = MujocoSettings.from_params(params, settings.mu) if "mujoco" in engines else None
    step = (lambda done, _: progress(done, total)) if progress else None
    robust = {}
    if robust_samples:
        tables, copies = [], []
        for number, planner, rows, row_seeds in picked:
            table = trials.iloc[rows]
            grasp, approach, orient, mus = perturbed_candidates(
                vectors(table, "grasp"),
                vectors(table, "approach"),
                vectors(table, "orient"),
                row_seeds,
                samples=robust_samples,
                pose_sigma_m=params.pose_sigma_m,
                angle_sigma_rad=params.angle_sigma_rad,
                mu=settings.mu,
                mu_sigma=params.mu_sigma,
            )
            columns = {
                f"{name}_{axis}": value[:, k]
                for name, value in zip(("grasp", "approach", "orient"), (grasp, approach, orient))
                for k, axis in enumerate("xyz")
            }
            # each copy graded once, in its trial, at its own friction coefficient
            preshape = np.repeat(table.preshape.to_numpy(), robust_samples)
            tables.append((number, pd.DataFrame({**columns, "preshape": preshape, "mu": mus})))
            copies.append(rows)
        results = run_trials(surface, hands, tables, settings, workers=workers, progress=step)
        for rows, result in zip(copies, results):
            robust.update({row: (fc, eps) for row, fc, eps in zip(rows, *robust_summary(result, robust_samples))})
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
        found = {check: [("", np.nan, np.nan)] * len(rows) for check in PHYSICS_CHECKS}
        for engine in engines:
            settings_of = physics_settings if engine == "pybullet" else mujoco_settings
            found.update(_physics(surface, parts, hands[number], table, settings_of, settings, step, engine=engine))
        for check, outcomes in found.items():
            frame[f"{check}_outcome"] = [outcome for outcome, _, _ in outcomes]
            frame[f"{check}_success"] = frame[f"{check}_outcome"] == "held"
            frame[f"{check}_slip_m"] = np.array([slip for _, slip, _ in outcomes], float)
            frame[f"{check}_turn_rad"] = np.array([turn for _, _, turn in outcomes], float)
        frame["mass_kg"] = object_mass(physics_settings, surface.vertices, surface.faces)
        frame["robust_fc"] = [robust.get(row, (np.nan, np.nan))[0] for row in rows]
        frame["robust_epsilon"] = [robust.get(row, (np.nan, np.nan))[1] for row in rows]
        frames.append(frame)
    return pd.concat(frames, ignore_index=True)


def _physics(surface, parts, hand, table, check_settings, settings, progress, *, engine):
    """{check: [(outcome, slip, turn) of each trial of ``table`` (one hand)]} of ``engine``:
    ``physics`` (pybullet, ``check_settings`` a PhysicsSettings) or ``mujoco`` and ``mujoco_open``
    (MuJoCo, ``check_settings`` a MujocoSettings; the open start from the trial's preshape); the
    hand model's point spacing from the trials' ``settings``."""
    from ..bullet import pybullet
    from ..hands.kinematics import hand_model

    checks = [name for name, check_engine in PHYSICS_CHECKS.items() if check_engine == engine]
    closed = table.outcome.astype(str).isin(CLOSED).to_numpy()
    found = {name: [("no_grasp", np.nan, np.nan)] * len(table) for name in checks}
    if not closed.any():
        if progress:
            progress(len(table), None)
        return found
    model = hand_model(hand, spacing=settings.link_point_spacing_m)
    refused = (pybullet.error, DegenerateGeometryError)  # the object or the hand could not be built
    try:
        if engine == "pybullet":
            from .physics import PhysicsCheck

            check = PhysicsCheck(
                surface.vertices, surface.faces, hand, model, parts=parts.parts, settings=check_settings
            )
        else:
            from .mujoco_check import MujocoCheck

            check = MujocoCheck(
                surface.vertices, surface.faces, hand, model, parts=parts.parts, settings=check_settings
            )
    except refused:  # every check of it fails
        for name in checks:
            found[name] = [("error", np.nan, np.nan) if closed[k] else row for k, row in enumerate(found[name])]
        check = None
    try:
        base, quaternion = vectors(table, "base"), table[[f"base_q{axis}" for axis in "xyzw"]].to_numpy(float)
        for k in np.flatnonzero(closed) if check else ():
            joints = np.asarray(table.joints.iloc[k], float)
            starts = [{}]
            if engine == "mujoco":
                opened = hand.preshape(table.preshape.iloc[k])
                starts.append({"open_joints": np.array([opened[joint] for joint in model.joints])})
            for name, start in zip(checks, starts):
                try:
                    result = check.check(base[k], quaternion[k], joints, **start)
                    found[name][k] = (result.outcome, result.slip_m, result.turn_rad)
                except pybullet.error:
                    found[name][k] = ("error", np.nan, np.nan)
    finally:
        if check:
            check.close()
    if progress:
        progress(len(table), None)
    return found


def check_rates(checks):
    """Of a checks table (or a slice of it): ``checked``; per lift-and-shake check
    (:data:`PHYSICS_CHECKS`) ``<check>_success_rate`` (held of the trials it ran on; NaN if
    none) and ``<check>_outcomes`` (counts); ``engines_agree`` (of the trials both pybullet's
    and MuJoCo's closed-pose checks ran on, the share where they agree on held; NaN if none);
    ``robust_fc`` (mean)."""
    found = {"checked": int(len(checks))}
    for check in PHYSICS_CHECKS:
        ran = checks[checks[f"{check}_outcome"] != ""]
        found[f"{check}_success_rate"] = float(ran[f"{check}_success"].mean()) if len(ran) else float("nan")
    both = ((checks.physics_outcome != "") & (checks.mujoco_outcome != "")).to_numpy()
    agree = checks.physics_success.to_numpy(bool)[both] == checks.mujoco_success.to_numpy(bool)[both]
    found["engines_agree"] = float(agree.mean()) if both.any() else float("nan")
    found["robust_fc"] = float(checks.robust_fc.mean()) if checks.robust_fc.notna().any() else float("nan")
    for check in PHYSICS_CHECKS:
        outcomes = checks[f"{check}_outcome"]
        found[f"{check}_outcomes"] = {outcome: int((outcomes == outcome).sum()) for outcome in PHYSICS_OUTCOMES}
    return found


def summary(checks):
    """The JSON-ready checks of a run: per planner (``mat``, ``baseline``, ``encompassing``) and per hand."""
    return {
        **{planner: check_rates(checks[checks.planner == planner]) for planner in PLANNERS},
        "per_hand": {
            hand: {
                planner: check_rates(checks[(checks.hand == hand) & (checks.planner == planner)])
                for planner in PLANNERS
            }
            for hand in sorted(checks.hand.unique())
        },
    }


def with_checks(trials, checks):
    """``trials`` (a copy) with the :data:`CHECK_COLUMNS` of ``checks`` (a checks table of the
    same trials, or None) on the checked rows: an unchecked trial (or one a check did not run
    on) has ``<check>_outcome`` "" and missing values (``<check>_success`` is a nullable boolean)."""
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
    for check in PHYSICS_CHECKS:
        outcome = frame[f"{check}_outcome"].astype(object).fillna("").astype(str)
        frame[f"{check}_outcome"] = outcome
        frame[f"{check}_success"] = frame[f"{check}_success"].astype("boolean").where(outcome != "")
    return frame

"""Ablation of the grasp trial's modelling choices: the same candidates run through
the trial engine once with the ``simulate`` params as they are and once per variant that
switches one choice, each graded by force closure and by the physics check, to tell which
choices move our Table I away from the paper's.

The candidates are those of the ``simulate`` stage (:func:`pipeline.trial.protocol.select_candidates`
and :func:`pipeline.trial.protocol.baseline_candidates`, the same seeds), optionally a seeded sample of
at most ``cap`` of each planner. Every variant runs all of them.

Physics success: the physics check (:class:`pipeline.checks.physics.PhysicsCheck`, its settings from
the ``checks`` params and the variant's friction ``mu``) of at most ``physics_trials`` of the
trials that closed on the object (outcome ``force_closure`` or ``no_force_closure``); the other
trials closed on nothing and count as not held. The checked trials are the first closed ones
in one seeded order of the planner's candidates, the same order for every variant, so the
variants share most of them; a closed hand checked before (the same pose, joints and
friction: variants that change only the grading) is not checked again. The rate is the
estimate ``closed trials / trials x held / checked``.

Table (:func:`ablate`): one row per hand (with trials), variant and planner; ``variant`` (the
``simulate`` key switched, ``default`` for the params as they are), ``setting`` (the values that
differ from the params: ``contact_tolerance_m=0.004``), ``planner`` (mat | baseline), ``trials``,
``force_closure_pct``, ``closed_pct`` (trials that closed on the object), ``physics_checked``,
``physics_held``, ``physics_success_pct`` (NaN with ``physics_trials`` 0, or when trials
closed but none was checked), and ``force_closure_delta`` and ``physics_success_delta``: the
change from the default row of the same hand and planner, in percentage points.
"""

import dataclasses

import numpy as np
import pandas as pd

from .. import seeds
from ..params import Params
from ..trial.engine import CLOSED, check_simulable
from ..trial.protocol import PLANNERS as ALL_PLANNERS
from ..trial.protocol import TrialPool, baseline_candidates, run_trials, select_candidates

#: the planners ablated: the MAT candidates against the baseline
PLANNERS = ALL_PLANNERS[:2]

#: (simulate key, value): the variants, each switching one modelling choice of the trial
VARIANTS = (
    ("retract_step_m", 0.0025),
    ("retract_step_m", 0.01),
    ("approach_step_m", 0.0005),
    ("approach_step_m", 0.002),
    ("approach_to_contact", False),
    ("approach_max_m", 0.0),
    ("contact_tolerance_m", 0.001),
    ("contact_tolerance_m", 0.004),
    ("coplanar_deg", 1.0),
    ("coplanar_deg", 15.0),
    ("max_link_contacts", 4),
    ("palm_contacts", False),
    ("mu", 1.0),
)
COLUMNS = (
    "hand",
    "variant",
    "setting",
    "planner",
    "trials",
    "force_closure_pct",
    "closed_pct",
    "physics_checked",
    "physics_held",
    "physics_success_pct",
    "force_closure_delta",
    "physics_success_delta",
)


def _text(value):
    return str(value).lower() if isinstance(value, bool) else f"{value:g}"


def variant_params(simulate, key, value):
    """The ``simulate`` params (SimulateParams) ``simulate`` with ``key`` set to ``value``, and
    the params that must follow it to stay valid: a contact tolerance keeps ``near_m`` at least
    and ``approach_step_m`` at most itself; an approach step is at most the tolerance."""
    changes = {key: value}
    if key == "contact_tolerance_m":
        changes.update(near_m=max(simulate.near_m, value), approach_step_m=min(simulate.approach_step_m, value))
    if key == "approach_step_m":
        changes[key] = min(value, simulate.contact_tolerance_m)
    return dataclasses.replace(simulate, **changes)


def settings_text(simulate, base):
    """``key=value`` of every ``simulate`` param that differs from ``base``, comma-separated."""
    return ", ".join(
        f"{field.name}={_text(getattr(simulate, field.name))}"
        for field in dataclasses.fields(simulate)
        if getattr(simulate, field.name) != getattr(base, field.name)
    )


def ablation_candidates(surface, candidates, hand, simulate, *, seed, cap=None):
    """The MAT candidates and the baseline's of ``hand`` (pandas.DataFrame each, candidate
    columns) as the ``simulate`` stage picks them with params ``simulate`` and ``seed``, each a
    seeded sample of at most ``cap`` rows (None: all)."""
    mat = select_candidates(candidates, hand.name, simulate.spheres_per_object, seeds.trial_spheres(seed))
    count = len(mat) if simulate.baseline_trials < 0 else simulate.baseline_trials
    tables = [mat, baseline_candidates(surface, hand, count, seeds.baseline(seed))]
    if cap is not None:
        rng = seeds.ablation_sample(seed)
        tables = [
            table if len(table) <= cap else table.iloc[np.sort(rng.choice(len(table), cap, replace=False))]
            for table in tables
        ]
    return [table.reset_index(drop=True) for table in tables]


def ablate(
    surface,
    candidates,
    hands,
    params=Params(),
    *,
    seed=None,
    cap=None,
    physics_trials=50,
    variants=VARIANTS,
    workers=1,
    parts=None,
    progress=None,
):
    """The ablation table (see the module docstring) of ``hands`` on one object.

    Parameters
    ----------
    surface : SurfaceSamples
        The object (its closed mesh, m).
    candidates : pandas.DataFrame
        The candidates table (stage ``candidates``) of ``hands``.
    hands : list of Hand
    params : Params
        ``simulate`` (the default row's settings, the spheres and baseline count), ``checks``
        (the physics check's settings) and ``seed``.
    seed : int, optional
        Overrides ``params.seed`` (the candidates' and the physics sample's seeds).
    cap : int, optional
        At most this many candidates per planner, a seeded sample (None: all).
    physics_trials : int
        Physics checks per hand, variant and planner at most; 0 = none, -1 = every closed trial.
    variants : sequence of (str, value)
        ``simulate`` keys and values, one switched at a time (:data:`VARIANTS`); a variant
        equal to the params or to an earlier variant is left out.
    workers : int
        Trial processes; results do not depend on it.
    parts : list of (v, 3) float, optional
        The object's convex parts for the physics check (computed from the mesh if not given).
    progress : callable(int, int), optional
        Called with the number of trials just finished and the total of every hand and variant.

    Returns
    -------
    pandas.DataFrame
    """
    check_simulable(surface)
    seed = params.seed if seed is None else seed
    base = params.simulate
    runs = [("default", base)]
    for key, value in variants:
        simulate = variant_params(base, key, value)
        if all(simulate != known for _, known in runs):
            runs.append((key, simulate))
    jobs = [(hand, ablation_candidates(surface, candidates, hand, base, seed=seed, cap=cap)) for hand in hands]
    jobs = [(hand, tables) for hand, tables in jobs if any(len(table) for table in tables)]  # no rows: no trials
    total = len(runs) * sum(len(table) for _, tables in jobs for table in tables)
    step = (lambda count, _: progress(count, total)) if progress else None

    if physics_trials and parts is None and jobs:
        from .physics import decompose

        parts = decompose(surface, vhacd_resolution=params.checks.vhacd_resolution).parts
    rows = []
    # one set of worker processes for every hand's and variant's calls
    with TrialPool() as trial_pool:
        for hand, tables in jobs:
            judge = _Physics(surface, hand, params, parts) if physics_trials else None
            order = [
                seeds.ablation_order(seed, hand.name, number).permutation(len(table))
                for number, table in enumerate(tables)
            ]
            try:
                for variant, simulate in runs:
                    results = run_trials(
                        surface,
                        [hand],
                        [(0, table) for table in tables],
                        simulate,
                        workers=workers,
                        pool=trial_pool,
                        progress=step,
                    )
                    for planner, outcomes, priority in zip(PLANNERS, results, order):
                        rows.append(
                            {
                                "hand": hand.name,
                                "variant": variant,
                                "setting": settings_text(simulate, base) or "params",
                                "planner": planner,
                                **_rates(outcomes, priority, physics_trials, judge, simulate.mu, planner),
                            }
                        )
            finally:
                if judge:
                    judge.close()
    return _deltas(pd.DataFrame(rows, columns=list(COLUMNS[:-2])))


def _rates(results, priority, physics_trials, judge, mu, planner):
    """The row's counts and rates of one variant's ``results`` (TrialResult list)."""
    count = len(results)
    outcomes = np.array([result.outcome for result in results], dtype=object)
    closed = np.flatnonzero(np.isin(outcomes, CLOSED))
    checked = held = 0
    success = np.nan
    if judge is not None:
        chosen = closed[np.argsort(priority[closed], kind="stable")]
        if physics_trials >= 0:
            chosen = chosen[:physics_trials]
        held = sum(judge.held(planner, number, results[number], mu) for number in chosen)
        checked = len(chosen)
        if checked:
            success = 100.0 * len(closed) / count * held / checked
        elif not len(closed):
            success = 0.0
    return {
        "trials": count,
        "force_closure_pct": 100.0 * float((outcomes == "force_closure").mean()) if count else np.nan,
        "closed_pct": 100.0 * len(closed) / count if count else np.nan,
        "physics_checked": checked,
        "physics_held": int(held),
        "physics_success_pct": success if count else np.nan,
    }


def _deltas(table):
    """``table`` with the changes from its default rows (same hand and planner), in points."""
    default = table[table.variant == "default"].set_index(["hand", "planner"])
    for column, rate in (
        ("force_closure_delta", "force_closure_pct"),
        ("physics_success_delta", "physics_success_pct"),
    ):
        reference = default[rate].reindex(pd.MultiIndex.from_frame(table[["hand", "planner"]])).to_numpy()
        table[column] = table[rate].to_numpy() - reference
    return table


class _Physics:
    """The physics checks of one hand on one object, one pybullet world per friction, each
    closed hand checked once."""

    def __init__(self, surface, hand, params, parts):
        self.surface, self.hand, self.params, self.parts = surface, hand, params, parts
        self.checks, self.seen = {}, {}

    def held(self, planner, number, result, mu):
        """Whether the closed hand of ``result`` (a TrialResult, ``number`` in ``planner``'s
        trials) holds the object at friction ``mu``; a check pybullet refuses is not held."""
        from ..bullet import pybullet

        key = (planner, number, mu, result.base_position, result.base_orientation, result.joint_positions)
        if key not in self.seen:
            try:
                check = self._check(mu).check(result.base_position, result.base_orientation, result.joint_positions)
                self.seen[key] = check.success
            except pybullet.error:
                self.seen[key] = False
        return self.seen[key]

    def _check(self, mu):
        if mu not in self.checks:
            from ..hands.kinematics import hand_model
            from .physics import PhysicsCheck, PhysicsSettings

            model = hand_model(self.hand, spacing=self.params.simulate.link_point_spacing_m)
            settings = PhysicsSettings(**self.params.checks.physics_settings(mu))
            self.checks[mu] = PhysicsCheck(
                self.surface.vertices, self.surface.faces, self.hand, model, parts=self.parts, settings=settings
            )
        return self.checks[mu]

    def close(self):
        for check in self.checks.values():
            check.close()


#: the object classes of docs/ablation.md (the built-in objects of params.yaml)
CLASSES = {
    "handled, hollow": ("mug", "kettle", "vase", "mug_pybullet"),
    "furniture": ("table", "chair"),
    "thin": ("glasses",),
    "organic": ("giraffe", "bust", "octopus", "duck", "bunny"),
    "round": ("torus", "soccerball"),
}
RATES = ("force_closure_pct", "force_closure_delta", "physics_success_pct", "physics_success_delta")


def class_means(tables, classes=CLASSES):
    """Each variant's rates and changes (points) per object class and planner, the mean over
    the class's runs (object and hand) that have trials.

    Parameters
    ----------
    tables : dict object name -> pandas.DataFrame
        :func:`ablate` tables.
    classes : dict class name -> sequence of object names

    Returns
    -------
    pandas.DataFrame
        ``class``, ``variant``, ``setting``, ``planner``, the means of :data:`RATES`, ``runs``
        and ``trials`` (their sum over the runs, per variant).
    """
    frames = []
    for name, members in classes.items():
        present = [tables[member].assign(object=member) for member in members if len(tables.get(member, ()))]
        if not present:
            continue
        grouped = pd.concat(present, ignore_index=True).groupby(["variant", "setting", "planner"], sort=False)
        means = grouped[list(RATES)].mean()
        means["runs"] = grouped.size()
        means["trials"] = grouped.trials.sum()
        frames.append(means.reset_index().assign(**{"class": name}))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def class_markdown(means, classes=CLASSES):
    """Markdown tables of :func:`class_means` (of ``classes``), one per class: per setting the
    MAT and baseline force-closure and physics success rates (default row) or their changes
    (points)."""

    def number(value, signed):
        if pd.isna(value):
            return "-"
        value = 0.0 if round(value, 1) == 0 else value  # no "-0.0"
        return f"{value:+.1f}" if signed else f"{value:.1f}"

    blocks = []
    for name, rows in means.groupby("class", sort=False):
        runs = rows[rows.variant == "default"].runs.max()
        lines = [
            f"**{name}** ({', '.join(classes.get(name, ()))}; {runs} runs)",
            "",
            "| setting | MAT fc | MAT held | baseline fc | baseline held |",
            "| --- | ---: | ---: | ---: | ---: |",
        ]
        for (variant, setting), pair in rows.groupby(["variant", "setting"], sort=False):
            signed = variant != "default"
            cells = []
            for planner in PLANNERS:
                row = pair[pair.planner == planner]
                columns = ("force_closure_delta", "physics_success_delta") if signed else RATES[::2]
                cells += [number(row[column].iloc[0], signed) if len(row) else "-" for column in columns]
            label = "default (% of trials)" if not signed else f"`{setting}`"
            lines.append(f"| {label} | " + " | ".join(cells) + " |")
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"

"""The report: the paper's Table I from the trials of every object, scale and hand, beside the
baseline's, plus the metrics and plot tables DVC shows (``dvc metrics show``, ``dvc plots show``).

Everything here takes the combined trials table (:func:`combine`) and returns tables, dicts or
Markdown text; the ``report`` stage does the reading and writing.
"""

import numpy as np
import pandas as pd

from ..checks.protocol import CHECK_COLUMNS, PHYSICS_CHECKS, with_checks
from ..trial.engine import OUTCOMES
from ..trial.protocol import PLANNERS

HAND_TITLES = {"armar3": "ARMAR-III", "barrett": "Barrett", "parallel_jaw": "parallel jaw"}
#: the lift-and-shake checks as the report names them
CHECK_TITLES = {"physics": "pybullet", "mujoco": "MuJoCo", "mujoco_open": "MuJoCo, open start"}
#: per run and planner: the held % of each check and the engines' agreement %
HELD_COLUMNS = ("physics_success_pct", "mujoco_success_pct", "mujoco_open_success_pct", "engines_agree_pct")
KEYS = ["object", "scale", "hand"]


def combine(tables, checks=None):
    """One trials table from ``{(object, scale, hand): trials}``, with ``object``, ``scale`` (float)
    and ``hand`` first; the per-run tables' columns follow (see :mod:`pipeline.trial.protocol`), then
    the check columns of the checked trials from ``checks`` (the same keys: the checks tables of
    :mod:`pipeline.checks.protocol`; see :func:`pipeline.checks.protocol.with_checks`)."""
    frames = []
    for (name, scale, hand), trials in tables.items():
        frame = with_checks(trials, (checks or {}).get((name, scale, hand))).drop(columns=["hand"], errors="ignore")
        frame.insert(0, "hand", hand)
        frame.insert(0, "scale", float(scale))
        frame.insert(0, "object", name)
        frames.append(frame)
    if not frames:
        return pd.DataFrame(columns=KEYS + ["planner", "outcome", "epsilon", *CHECK_COLUMNS])
    combined = pd.concat(frames, ignore_index=True)
    combined["outcome"] = pd.Categorical(combined.outcome.astype(str), categories=OUTCOMES)
    return combined


def results(trials, runs):
    """One row per run (object, scale, hand) and planner (:data:`pipeline.trial.protocol.PLANNERS`) side
    by side: trials, force-closure rate (%), mean epsilon over the force-closure trials, checks
    (each lift-and-shake's held %: :data:`HELD_COLUMNS`, with the share of trials both engines
    checked on which pybullet and MuJoCo agree), and the MAT outcome counts.

    Parameters
    ----------
    trials : pandas.DataFrame
        From :func:`combine`.
    runs : list of (object, scale, hand)
        Every run the params ask for, in the report's order; a run without trials (an object
        too big for the hand has no candidates) gets 0 trials and NaN rates.
    """
    index = pd.MultiIndex.from_tuples([(name, float(scale), hand) for name, scale, hand in runs], names=KEYS)
    closed = trials.outcome == "force_closure"
    held = {f"{check}_held": trials[f"{check}_success"].astype(float) for check in PHYSICS_CHECKS}  # NaN: not checked
    grouped = trials.assign(
        closed=closed,
        closed_epsilon=trials.epsilon.where(closed),
        checked=_checked(trials),
        agree=_engines_agree(trials),
        **held,
    ).groupby(KEYS + ["planner"], observed=True)
    table = pd.DataFrame(
        {
            "trials": grouped.size(),
            "force_closure_pct": 100.0 * grouped.closed.mean(),
            "mean_epsilon": grouped.closed_epsilon.mean(),
            "checked": grouped.checked.sum(),
            **{f"{check}_success_pct": 100.0 * grouped[f"{check}_held"].mean() for check in PHYSICS_CHECKS},
            "engines_agree_pct": 100.0 * grouped.agree.mean(),
            "robust_fc_pct": 100.0 * grouped.robust_fc.mean(),
        }
    ).unstack("planner")
    frame = pd.DataFrame(index=index)
    for planner in PLANNERS:
        for column in (
            "trials",
            "force_closure_pct",
            "mean_epsilon",
            "checked",
            *HELD_COLUMNS,
            "robust_fc_pct",
        ):
            values = table[(column, planner)] if (column, planner) in table.columns else pd.Series(dtype=float)
            frame[f"{planner}_{column}"] = values.reindex(index)
    for planner in PLANNERS:
        for column in ("trials", "checked"):
            frame[f"{planner}_{column}"] = frame[f"{planner}_{column}"].fillna(0).astype(int)
    mat = trials[trials.planner == "mat"]
    outcomes = mat.groupby(KEYS, observed=True).outcome.value_counts().unstack(fill_value=0)
    for outcome in OUTCOMES:
        counts = outcomes[outcome] if outcome in outcomes.columns else pd.Series(dtype=int)
        frame[outcome] = counts.reindex(index).fillna(0).astype(int)
    return frame.reset_index()


def _checked(trials):
    """Trials that the check stage sampled (a lift-and-shake, robust force closure or both)."""
    ran = np.logical_or.reduce([(trials[f"{check}_outcome"] != "").to_numpy() for check in PHYSICS_CHECKS])
    return pd.Series(ran, index=trials.index) | trials.robust_fc.notna()


def _engines_agree(trials):
    """1.0 where pybullet's and MuJoCo's closed-pose checks agree on held, 0.0 where not, NaN
    where either did not run (a float Series)."""
    both = (trials.physics_outcome != "") & (trials.mujoco_outcome != "")
    agree = trials.physics_outcome.eq("held") == trials.mujoco_outcome.eq("held")
    return agree.astype(float).where(both)


def metrics(trials, table):
    """Headline numbers for ``dvc metrics show``: force-closure rate of each planner overall (the
    encompassing candidates' too), of MAT and the baseline per hand and per scale (from
    ``trials``), and in how many runs MAT beats the baseline (from :func:`results`' ``table``)."""

    def rates(frame):
        closed = frame.outcome == "force_closure"
        checked = int(_checked(frame).sum())
        robust = frame.robust_fc.dropna()
        agree = _engines_agree(frame).dropna()

        # to 1e-6: the report prints them as percent to 0.1, and a first rounding to 1e-4 moved
        # some across (held in 180 of 1,300 checks: 0.13846 -> 0.1385 -> 13.9 %)
        def mean(values):
            return round(float(values.mean()), 6) if len(values) else float("nan")

        return {
            "force_closure_rate": round(float(closed.mean()), 6) if len(frame) else float("nan"),
            "trials": int(len(frame)),
            **{
                f"{check}_success_rate": mean(frame[f"{check}_success"].dropna().astype(float))
                for check in PHYSICS_CHECKS
            },
            "engines_agree": mean(agree),
            "robust_fc": mean(robust),
            "checked": checked,
        }

    out = {planner: rates(trials[trials.planner == planner]) for planner in PLANNERS}
    for key in ("hand", "scale"):
        for rate, prefix in (
            ("force_closure_rate", ""),
            *((f"{check}_success_rate", f"{check}_") for check in PHYSICS_CHECKS),
            ("engines_agree", "engines_agree_"),
            ("robust_fc", "robust_fc_"),
        ):
            out[f"{prefix}per_{key}"] = {
                str(value): {planner: rates(group[group.planner == planner])[rate] for planner in ("mat", "baseline")}
                for value, group in trials.groupby(key, sort=True)
            }
    compared = table.dropna(subset=["mat_force_closure_pct", "baseline_force_closure_pct"])
    out["runs_compared"] = int(len(compared))
    out["runs_mat_above_baseline"] = int((compared.mat_force_closure_pct > compared.baseline_force_closure_pct).sum())
    return out


def plot_tables(table, trials, *, bins=20):
    """Tables for ``dvc plots``: from :func:`results`' ``table``, the force-closure % of each run
    (``run`` = "object xscale hand", 0 where there were no trials) per planner, with the physics
    success % and the mean robust force closure (%) of its checked trials (empty: none); from ``trials``,
    the epsilon histograms of the force-closure trials (counts per bin over [0, largest epsilon])."""
    run = table.object + " x" + table.scale.map("{:g}".format) + " " + table.hand
    force_closure = {
        planner: pd.DataFrame(
            {
                "run": run,
                "force_closure_pct": table[f"{planner}_force_closure_pct"].fillna(0.0).round(2),
                **{column: table[f"{planner}_{column}"].round(2) for column in HELD_COLUMNS},
                "robust_fc_pct": table[f"{planner}_robust_fc_pct"].round(2),
            }
        )
        for planner in ("mat", "baseline")
    }
    closed = trials[trials.outcome == "force_closure"]
    top = float(closed.epsilon.max()) if len(closed) else 1.0
    edges = np.linspace(0.0, top if top > 0 else 1.0, bins + 1)
    histogram = pd.DataFrame({"epsilon": np.round((edges[:-1] + edges[1:]) / 2, 6)})
    for planner in ("mat", "baseline"):
        histogram[planner] = np.histogram(closed.epsilon[closed.planner == planner], bins=edges)[0]
    return force_closure, histogram


def calibration_plots(calibration):
    """``{score: table}`` for ``dvc plots`` from :func:`calibration`: per bin, its edges, each
    planner's held % per check (``mat``, ``baseline``: pybullet's; ``mat_mujoco``,
    ``baseline_mujoco``, ``mat_mujoco_open``, ...; empty where no trial was checked) and the
    trials each check ran on (``mat_checked``, ``mat_mujoco_checked``, ...)."""
    plots = {}
    rounded = calibration.assign(low=calibration.low.round(6), high=calibration.high.round(6))
    for score, rows in rounded.groupby("score", sort=False):
        frame = None
        for check, part in rows.groupby("check", sort=False):
            wide = part.pivot(
                index=["bin", "low", "high"], columns="planner", values=["physics_success_pct", "checked"]
            )
            suffix = "" if check == "physics" else f"_{check}"
            held = wide["physics_success_pct"].reindex(columns=["mat", "baseline"]).round(2)
            held.columns = [f"{planner}{suffix}" for planner in held.columns]
            for planner in ("mat", "baseline"):
                held[f"{planner}{suffix}_checked"] = wide["checked"][planner].fillna(0).astype(int)
            frame = held if frame is None else frame.join(held)
        plots[score] = frame.reset_index()
    return plots


def timing_table(timings):
    """Per-stage wall time from ``[{"stage", "seconds", "process_seconds", "record_seconds"}, ...]``:
    runs, total, median and largest seconds of the work, the part of it spent recording (.rrd,
    rerun's import included), and the total of whole processes (imports included), in pipeline order."""
    order = ["sample", "medial_axis", "mat", "sphere_grid", "classify", "concavity", "candidates", "simulate"]
    order += ["decompose", "check", "report"]
    frame = pd.DataFrame(timings, columns=["stage", "seconds", "process_seconds", "record_seconds"])
    frame["process_seconds"] = frame.process_seconds.fillna(frame.seconds)
    frame["record_seconds"] = frame.record_seconds.fillna(0.0)
    table = frame.groupby("stage").agg(
        runs=("seconds", "size"),
        total_s=("seconds", "sum"),
        median_s=("seconds", "median"),
        max_s=("seconds", "max"),
        record_total_s=("record_seconds", "sum"),
        process_total_s=("process_seconds", "sum"),
    )
    return table.reindex([stage for stage in order if stage in table.index]).reset_index()


def _pct(value, count):
    return "-" if count == 0 or pd.isna(value) else f"{value:.1f}"


def table_one(table, planner):
    """Markdown of the paper's Table I layout for one planner: a row per object, a column per
    hand and scale, cells the force-closure % ("-": no trials, the object had no candidates);
    when any trial was checked, followed by the held % in pybullet's and in MuJoCo's
    lift-and-shake (from the closed pose) and the mean robust force closure (%) of the checked
    trials in brackets."""
    hands = list(dict.fromkeys(table.hand))
    scales = list(dict.fromkeys(table.scale))
    checked = bool(table[f"{planner}_checked"].sum()) if f"{planner}_checked" in table.columns else False
    header = (
        "| object | "
        + " | ".join(f"{HAND_TITLES.get(hand, hand)} x{scale:g}" for hand in hands for scale in scales)
        + " |"
    )
    lines = [header, "| --- |" + " ---: |" * (len(hands) * len(scales))]
    cells = table.set_index(KEYS)
    for name in dict.fromkeys(table.object):
        row = [
            _cell(cells.loc[key], planner, checked) if key in cells.index else ""
            for key in ((name, scale, hand) for hand in hands for scale in scales)
        ]
        lines.append(f"| {name} | " + " | ".join(row) + " |")
    return "\n".join(lines)


def _cell(row, planner, checked):
    text = _pct(row[f"{planner}_force_closure_pct"], row[f"{planner}_trials"])
    if checked and row[f"{planner}_checked"]:
        values = [
            row[f"{planner}_{column}"] for column in ("physics_success_pct", "mujoco_success_pct", "robust_fc_pct")
        ]
        text += " (" + " / ".join(_pct(value, 1) for value in values) + ")"
    return text


def calibration(trials, *, bins=10):
    """Held in each lift-and-shake (:data:`pipeline.checks.protocol.PHYSICS_CHECKS`) against the
    analytic scores, per planner: :func:`calibration_of` of each check, a ``check`` column first."""
    frames = [calibration_of(trials, check, bins=bins) for check in PHYSICS_CHECKS]
    return pd.concat([frame.assign(check=check) for frame, check in zip(frames, PHYSICS_CHECKS)], ignore_index=True)[
        ["check", *frames[0].columns]
    ]


def calibration_of(trials, check="physics", *, bins=10):
    """Held in the ``check`` lift-and-shake (``physics``: pybullet's) of the trials it ran on,
    against their analytic scores, per planner: a row per ``score`` (``epsilon``: a bin of the
    trials without force closure, then deciles of the force-closure trials' epsilon over both
    planners; ``robust_fc``: ``bins`` equal bins of [0, 1]) and bin, with its ``low`` and
    ``high`` edges, the ``checked`` trials and their ``physics_success_pct`` (the held %; NaN
    when none)."""
    checked = trials[trials[f"{check}_success"].notna()]
    held = checked[f"{check}_success"].astype(float).to_numpy()
    closed = (checked.outcome == "force_closure").to_numpy()
    positive = checked.epsilon.to_numpy(float)[closed]
    edges = np.quantile(positive, np.linspace(0, 1, bins + 1)) if len(positive) else np.zeros(bins + 1)
    epsilon_bin = np.where(closed, 1 + np.clip(np.searchsorted(edges, checked.epsilon, "right") - 1, 0, bins - 1), 0)
    robust_edges = np.linspace(0.0, 1.0, bins + 1)
    robust_bin = np.clip(np.searchsorted(robust_edges, checked.robust_fc.fillna(-1.0), "right") - 1, -1, bins - 1)
    rows = []
    for score, numbers, lows, highs in (
        ("epsilon", epsilon_bin, np.r_[0.0, edges[:-1]], np.r_[0.0, edges[1:]]),
        ("robust_fc", robust_bin, robust_edges[:-1], robust_edges[1:]),
    ):
        for planner in ("mat", "baseline"):
            mine = (checked.planner == planner).to_numpy()
            for number in range(len(lows)):
                inside = mine & (numbers == number)
                rows.append(
                    {
                        "score": score,
                        "planner": planner,
                        "bin": number,
                        "low": float(lows[number]),
                        "high": float(highs[number]),
                        "checked": int(inside.sum()),
                        "physics_success_pct": 100.0 * held[inside].mean() if inside.any() else float("nan"),
                    }
                )
    return pd.DataFrame(rows)


def runs_table(table):
    """Markdown with a row per object x scale x hand: both planners' rates, trials and mean
    epsilon, and the MAT trials' outcome counts."""
    lines = [
        "| object | scale | hand | MAT % | baseline % | MAT trials | baseline trials | MAT mean eps "
        "| baseline mean eps | MAT held % | baseline held % | MAT MuJoCo held % | baseline MuJoCo held % "
        "| MAT robust % | baseline robust % | " + " | ".join(OUTCOMES) + " |",
        "| --- | ---: | --- |" + " ---: |" * (12 + len(OUTCOMES)),
    ]
    for row in table.itertuples(index=False):
        epsilon = [
            ("-" if pd.isna(value) else f"{value:.4f}") for value in (row.mat_mean_epsilon, row.baseline_mean_epsilon)
        ]
        counts = [str(getattr(row, outcome)) for outcome in OUTCOMES]
        checks = [
            _pct(getattr(row, f"{planner}_{column}"), getattr(row, f"{planner}_checked"))
            for column in ("physics_success_pct", "mujoco_success_pct", "robust_fc_pct")
            for planner in ("mat", "baseline")
        ]
        lines.append(
            f"| {row.object} | {row.scale:g} | {row.hand} | {_pct(row.mat_force_closure_pct, row.mat_trials)} "
            f"| {_pct(row.baseline_force_closure_pct, row.baseline_trials)} | {row.mat_trials} "
            f"| {row.baseline_trials} | {epsilon[0]} | {epsilon[1]} | " + " | ".join(checks + counts) + " |"
        )
    return "\n".join(lines)


def _checks_summary(mat, baseline):
    if not mat["checked"] and not baseline["checked"]:
        return []

    def rate(value):
        return "-" if np.isnan(value) else f"{100 * value:.1f} %"

    return [
        f"Checked trials (a seeded sample per run and planner, `checks.parquet`): MAT {mat['checked']}, held in "
        f"pybullet's lift-and-shake {rate(mat['physics_success_rate'])}, in MuJoCo's "
        f"{rate(mat['mujoco_success_rate'])} (from the open hand {rate(mat['mujoco_open_success_rate'])}), mean "
        f"robust force closure {rate(mat['robust_fc'])}; baseline {baseline['checked']}, "
        f"{rate(baseline['physics_success_rate'])}, {rate(baseline['mujoco_success_rate'])} "
        f"({rate(baseline['mujoco_open_success_rate'])}) and {rate(baseline['robust_fc'])}. Table I's cells then "
        "read: force closure % (held % pybullet / held % MuJoCo / robust force closure %).",
        "",
    ]


def engines_table(metrics_dict):
    """Markdown: per hand and planner, the held % of each lift-and-shake and the engines'
    agreement (from :func:`metrics`)."""
    lines = [
        "| hand | planner | "
        + " | ".join(f"held % {title}" for title in CHECK_TITLES.values())
        + " | engines agree % |",
        "| --- | --- |" + " ---: |" * (len(CHECK_TITLES) + 1),
    ]
    for hand in metrics_dict["per_hand"]:
        for planner in ("mat", "baseline"):
            values = [metrics_dict[f"{check}_per_hand"][hand][planner] for check in CHECK_TITLES]
            values.append(metrics_dict["engines_agree_per_hand"][hand][planner])
            cells = ["-" if np.isnan(value) else f"{100 * value:.1f}" for value in values]
            lines.append(f"| {HAND_TITLES.get(hand, hand)} | {planner} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _engines_section(metrics_dict):
    mat = metrics_dict["mat"]
    if np.isnan(mat["engines_agree"]) and not any(metrics_dict[planner]["checked"] for planner in ("mat", "baseline")):
        return []
    return [
        "## The lift-and-shake on two engines",
        "",
        "The same checked trials, held in pybullet's check (rigid point contacts, `physics_*`), in MuJoCo's "
        "(soft contacts, elliptic cones, torsional friction; `mujoco_*`) and in MuJoCo's from the open hand "
        "closing on the free object (`mujoco_open_*`); the engines agree where both say held or both say "
        "not (closed-pose starts). The object weighs its volume x `checks.density_kg_m3`, at most "
        "`checks.payload_kg` (the graspable-mass rule: a heavy object is checked at the payload).",
        "",
        engines_table(metrics_dict),
        "",
    ]


def markdown(table, metrics_dict, timings, *, figures=(), settings=""):
    """The whole report as Markdown.

    Parameters
    ----------
    table : pandas.DataFrame
        From :func:`results`.
    metrics_dict : dict
        From :func:`metrics`.
    timings : pandas.DataFrame
        From :func:`timing_table`.
    figures : list of (caption, relative path)
    settings : str
        One line on the protocol (spheres per object, mu, seed), put under the title.
    """
    mat, baseline = metrics_dict["mat"], metrics_dict["baseline"]
    compared = table.dropna(subset=["mat_force_closure_pct", "baseline_force_closure_pct"])
    losing = compared[compared.mat_force_closure_pct <= compared.baseline_force_closure_pct]
    empty = table[table.mat_trials == 0]

    def rate(value):
        return "-" if np.isnan(value) else f"{100 * value:.1f} %"

    parts = [
        "# Grasp planning on the grid of medial spheres: results",
        "",
        settings,
        "",
        f"MAT candidates: {mat['trials']} trials, force closure {rate(mat['force_closure_rate'])}; "
        f"surface-normal baseline: {baseline['trials']} trials, {rate(baseline['force_closure_rate'])}. "
        f"MAT is above the baseline in {metrics_dict['runs_mat_above_baseline']} of "
        f"{metrics_dict['runs_compared']} runs (object x scale x hand) that have trials.",
        "",
        *_checks_summary(mat, baseline),
        "## Table I: force-closure % of the MAT candidates",
        "",
        table_one(table, "mat"),
        "",
        "## The same for the surface-normal baseline",
        "",
        table_one(table, "baseline"),
        "",
        *_engines_section(metrics_dict),
        "## Every run",
        "",
        "Mean epsilon is over the force-closure trials (Ferrari-Canny L1, torque over the object's "
        "largest radius); the outcome counts are the MAT trials'.",
        "",
        runs_table(table),
        "",
    ]
    if len(losing):
        parts += [
            "Runs where MAT is not above the baseline: "
            + ", ".join(
                f"{row.object} x{row.scale:g} {row.hand} ({row.mat_force_closure_pct:.1f} vs "
                f"{row.baseline_force_closure_pct:.1f})"
                for row in losing.itertuples()
            )
            + ".",
            "",
        ]
    if len(empty):
        parts += [
            "Runs without MAT trials (no sphere of the reduced set fits the hand): "
            + ", ".join(f"{row.object} x{row.scale:g} {row.hand}" for row in empty.itertuples())
            + ".",
            "",
        ]
    if table.encompassing_trials.sum():
        around = metrics_dict["encompassing"]
        parts += [
            "## Grasps that encompass a concavity (paper V, future work)",
            "",
            f"Candidates around the outside of a container (stage `concavity`): {around['trials']} trials, "
            f"force closure {rate(around['force_closure_rate'])}"
            + (
                f", held in the physics check {rate(around['physics_success_rate'])} and robust force closure "
                f"{rate(around['robust_fc'])} of {around['checked']} checked"
                if around["checked"]
                else ""
            )
            + '. Runs without such candidates read "-".',
            "",
            table_one(table, "encompassing"),
            "",
        ]
    parts += [
        "## Time per stage",
        "",
        "Wall seconds of each stage's work, of which the part spent writing rerun recordings (rerun's "
        "import included); the last column adds the Python start-up and imports of its processes (DVC's "
        "own bookkeeping is not included).",
        "",
        "| stage | runs | total s | median s | max s | recording s | with start-up s |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    parts += [
        f"| {row.stage} | {row.runs} | {row.total_s:.1f} | {row.median_s:.2f} | {row.max_s:.2f} "
        f"| {row.record_total_s:.1f} | {row.process_total_s:.1f} |"
        for row in timings.itertuples()
    ]
    recorded, whole = timings.record_total_s.sum(), timings.process_total_s.sum()
    if recorded:
        parts += [
            "",
            f"Recording took {recorded:.1f} s of the stages' {whole:.1f} s: it added "
            f"{100 * recorded / max(whole - recorded, 1e-9):.1f} % to the run (target: at most 20 %).",
        ]
    if figures:
        parts += ["", "## Figures", ""]
        for caption, path in figures:
            parts += [f"**{caption}**", "", f"![{caption}]({path})", ""]
    return "\n".join(parts).rstrip() + "\n"

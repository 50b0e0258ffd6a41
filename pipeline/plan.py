"""Run every implemented stage on one object, outside DVC, timing each stage."""

import dataclasses
import time
from pathlib import Path

import numpy as np

from . import seeds
from .artefacts import atomic_write, json_bytes, write_table
from .checks.protocol import summary as checks_summary
from .dag import ARTEFACTS, STAGES
from .dag import function as stage_function
from .geometry.concavity import SECTIONS as CONCAVITY_SECTIONS
from .geometry.objects import RepairWarning, source_key
from .geometry.symmetry import CLASSES, INTERIOR
from .hands.spec import get_hand
from .params import Params
from .pool import default_workers
from .stage_io import warning_line
from .trial.protocol import summary as trial_summary

#: file of each artefact a chain run makes, by its key in :func:`run_chain`'s result: the stage
#: that makes it (``trials`` and ``contacts`` by their own names), and its table name; files named
#: as in the DVC stages
ARTEFACT_KEYS = {
    (stage.name if len(stage.outputs) == 1 else output): output for stage in STAGES for output in stage.outputs
}
ARTEFACT_NAMES = {key: ARTEFACTS[output] for key, output in ARTEFACT_KEYS.items()}


def run_chain(
    source,
    params=Params(),
    *,
    scale=1.0,
    shape=None,
    seed=None,
    hands=None,
    simulate=False,
    workers=None,
    progress=None,
    trial_progress=None,
):
    """Compute every stage's artefact for one object, in memory.

    Parameters
    ----------
    source : str
        See :mod:`pipeline.geometry.objects`.
    params : Params
    seed : int, optional
        Overrides ``params.seed``.
    hands : list of str, optional
        Overrides ``params.candidates.hands`` (built-in names or hand spec paths).
    simulate : bool
        Also run the grasp trials (``params.simulate``) and their checks (``params.checks``):
        adds ``trials``, ``contacts``, ``decompose`` (the convex parts) and ``check``.
    workers : int, optional
        Overrides ``params.simulate.workers``.
    progress : callable(str), optional
        Called with a one-line message after each stage.
    trial_progress : callable(int, int), optional
        Called with the trials just finished and the total (see :func:`pipeline.trial.protocol.simulate`).

    Returns
    -------
    artefacts : dict stage -> artefact
    timings_s : dict stage -> seconds
    """
    seed = params.seed if seed is None else seed
    hand_specs = [get_hand(name) for name in (hands or params.candidates.hands)]  # fail before any work
    # the keywords each stage's function takes beyond its inputs and its whole params section
    extra = {
        "sample": dict(
            source=source,
            scale=scale,
            shape=shape,
            rng=seeds.surface_samples(seed),
            source_key=source_key(source, shape),
        ),
        "concavity": dict(
            seed=seed,
            **{name: dataclasses.asdict(getattr(params, name)) for name in CONCAVITY_SECTIONS},
        ),
        "candidates": dict(
            hands=hand_specs,
            approach_directions=params.candidates.approach_directions,
            flipped_candidates=params.candidates.flipped_candidates,
            centre_rims=params.candidates.centre_rims,
            max_width_ratio=params.concavity.max_width_ratio,
        ),
        "simulate": dict(
            hands=hand_specs,
            spheres_per_object=params.simulate.spheres_per_object,
            baseline_trials=params.simulate.baseline_trials,
            seed=seed,
            workers=default_workers(params.simulate.workers if workers is None else workers),
            settings=params.simulate,
            progress=trial_progress,
        ),
        "decompose": dict(vhacd_resolution=params.checks.vhacd_resolution, scale=scale),
        "check": dict(
            hands=hand_specs,
            seed=seed,
            settings=params.simulate,
            workers=default_workers(params.simulate.workers if workers is None else workers),
        ),
    }
    made, artefacts, timings = {}, {}, {}
    for entry in STAGES:
        if entry.name == "simulate" and not simulate:
            break
        keywords = dataclasses.asdict(getattr(params, entry.section)) if entry.section else {}
        start = time.perf_counter()
        result = stage_function(entry)(*(made[name] for name in entry.inputs), **keywords, **extra.get(entry.name, {}))
        timings[entry.name] = time.perf_counter() - start
        made.update(zip(entry.outputs, result if len(entry.outputs) > 1 else (result,)))
        if progress:
            progress(f"{entry.name}: {timings[entry.name]:.2f} s")
    for key, name in ARTEFACT_KEYS.items():
        if name in made:
            artefacts[key] = made[name]
    return artefacts, timings


def summary(artefacts, timings, *, source, scale, seed, hands=(), warnings=()):
    """The JSON-ready summary of a chain run: counts, per-stage ``timings_s`` and ``warnings``.

    ``hands`` (the names or spec paths planned for) puts each hand into ``candidates``, 0 for
    one with none, which also adds a warning; ``warnings`` are the chain's own (one line each).
    """
    spheres = artefacts["mat"]
    counts = artefacts["candidates"].groupby("hand").size()
    candidates = {
        **{get_hand(hand).name: 0 for hand in hands},
        **{str(hand): int(count) for hand, count in counts.items()},
    }
    return {
        "source": source,
        "scale": scale,
        "seed": seed,
        "counts": {
            "surface_samples": len(artefacts["sample"].points),
            "medial_axis_points": len(artefacts["medial_axis"].radii),
            "medial_spheres": len(spheres),
            "spheres_object_angle_ge_120deg": int((spheres.object_angle >= np.radians(120)).sum()),
        },
        "radius_m": {
            "min": float(spheres.radii.min()),
            "median": float(np.median(spheres.radii)),
            "max": float(spheres.radii.max()),
        },
        "classes": dict(zip(CLASSES, np.bincount(artefacts["classify"].class_id, minlength=len(CLASSES)).tolist())),
        "candidates": candidates,
        **(
            {
                "concavities": {
                    "counted": int(artefacts["concavity"].counted.sum()),
                    "width_m": artefacts["concavity"].width[artefacts["concavity"].counted].tolist(),
                    "encompassing_spheres": len(artefacts["concavity"]),
                }
            }
            if "concavity" in artefacts
            else {}
        ),
        **(trial_summary(artefacts["trials"]) if "trials" in artefacts else {}),
        **({"checks": checks_summary(artefacts["check"])} if "check" in artefacts else {}),
        "keys": {stage: artefact.key for stage, artefact in artefacts.items() if hasattr(artefact, "key")},
        "timings_s": {stage: round(seconds, 4) for stage, seconds in timings.items()},
        "warnings": list(warnings)
        + [
            no_candidates_warning(get_hand(hand), artefacts["classify"], source)
            for hand in hands
            if not candidates[get_hand(hand).name]
        ],
    }


def no_candidates_warning(hand, symmetry, source):
    """Why ``hand`` (a Hand) gets no grasp candidate on the reduced set ``symmetry``: one line."""
    diameters = 2.0 * np.asarray(symmetry.radii)
    if not len(diameters):
        return f"hand {hand.name}: no grasp candidates on {source}: the reduced set holds no medial sphere"
    if (diameters > hand.max_graspable_diameter).all():
        return (
            f"hand {hand.name}: no grasp candidates on {source}: all {len(diameters)} reduced medial spheres "
            f"are wider than its max_graspable_diameter {hand.max_graspable_diameter:g} m "
            f"(narrowest {diameters.min():.3g} m)"
        )
    return (
        f"hand {hand.name}: no grasp candidates on {source}: its graspable medial spheres are all of "
        f"class {CLASSES[INTERIOR]}"
    )


def warning_lines(caught):
    """One line per Python warning caught while the chain ran (``warnings.catch_warnings(record=True)``):
    a pipeline repair as its message, any other with its category and origin."""
    return [
        str(caught_warning.message)
        if issubclass(caught_warning.category, RepairWarning)
        else warning_line(caught_warning)
        for caught_warning in caught
    ]


def write_plan(out_dir, artefacts, summary_dict):
    """Write each artefact under its DVC name and ``summary.json`` into ``out_dir``."""
    out_dir = Path(out_dir)
    for stage, artefact in artefacts.items():
        if ARTEFACT_NAMES[stage].endswith(".parquet"):
            write_table(out_dir / ARTEFACT_NAMES[stage], artefact)
        else:
            artefact.save(out_dir / ARTEFACT_NAMES[stage])
    text = json_bytes(summary_dict, indent=2)
    atomic_write(out_dir / "summary.json", lambda stream: stream.write(text))

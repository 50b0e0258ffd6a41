"""Batch planning: the per-object chain (sample ... simulate) over a folder of meshes, on Ray.

DVC stays the tool for the reproducible default run; a dataset of thousands of meshes runs the
very same :func:`pipeline.plan.run_chain` as Ray tasks, one object per task, on an embedded
local Ray (the machine's cores) or on an existing cluster.

Output, two folders of parquet files that pandas or any parquet reader opens as one table each
(``pd.read_parquet(OUT / "objects")``):

- ``OUT/objects/<name>.parquet``: one row per object: ``status`` (``ok``; ``error``: the mesh
  or a param was refused, ``reason`` says why; ``failed``: the task raised or its worker crashed
  twice), counts, force-closure rates and the object's ``key``;
- ``OUT/trials/<name>.parquet``: every trial of the object, all hands, ``object`` in front.

The driver writes each object's files as its result arrives, trials first and the summary row
last, each atomically: the summary row marks the object done. ``key`` hashes the mesh file's
bytes, the scale, the seed, the hands and every param the chain reads, so a rerun skips each
object done with the same key, an interrupted batch resumes where it stopped, and no object is
written twice. Memory stays bounded: at most ``2 x workers`` objects are in flight.
"""

import dataclasses
import logging
import os
import re
import time
from pathlib import Path

import pandas as pd

from .artefacts import SCHEMA_VERSION, content_key, write_table
from .errors import BadInputError, PipelineError
from .geometry.objects import mesh_files, source_key

SUMMARY_COLUMNS = {
    "object": str,
    "status": str,
    "reason": str,
    "key": str,
    "source": str,
    "samples": "Int64",
    "medial_spheres": "Int64",
    "reduced_spheres": "Int64",
    "candidates": "Int64",
    "mat_trials": "Int64",
    "force_closure_rate": float,
    "mean_epsilon": float,
    "baseline_trials": "Int64",
    "baseline_force_closure_rate": float,
    "physics_success_rate": float,
    "baseline_physics_success_rate": float,
    "robust_fc": float,
    "baseline_robust_fc": float,
    "encompassing_trials": "Int64",
    "encompassing_force_closure_rate": float,
    "seconds": float,
}
DONE = ("ok", "error")  # outcomes that the same key would give again; "failed" is retried


def find_meshes(folder):
    """Mesh files under ``folder`` (recursive, in natural order) and their object names.

    ``folder`` may be ``pybullet:DIR``, a folder of the installed pybullet_data package (the
    demo dataset: ``pybullet:random_urdfs``). Names are file stems when unique, else the path
    relative to ``folder`` with ``_`` for ``/``.

    Returns
    -------
    list of (name, absolute Path)
    """
    folder, files = mesh_files(folder)
    stems = [relative.stem for relative, _ in files]
    unique = len(set(stems)) == len(stems)
    names = [stem if unique else "_".join(relative.with_suffix("").parts) for stem, (relative, _) in zip(stems, files)]
    names = [re.sub(r"[^A-Za-z0-9_.-]", "_", name) for name in names]
    names = [f"mesh{name}" if name[0] in "_." else name for name in names]  # parquet readers skip _* and .* files
    if len(set(names)) < len(names):  # two files would write the same output files
        clash = next(name for name in names if names.count(name) > 1)
        raise BadInputError(f"{folder}: two meshes give the object name {clash!r}; rename one")
    return [(name, path) for name, (_, path) in zip(names, files)]


def object_key(path, *, scale, seed, hands, params):
    """Content key of one object's batch run: the mesh bytes and everything the chain reads."""
    used = {
        section: dataclasses.asdict(getattr(params, section))
        for section in (
            "sample",
            "medial_axis",
            "mat",
            "sphere_grid",
            "classify",
            "concavity",
            "candidates",
            "simulate",
            "checks",
        )
    }
    used["candidates"].pop("hands")
    used["simulate"].pop("workers")  # results do not depend on it
    from .hands.spec import get_hand

    specs = [dataclasses.asdict(get_hand(hand)) for hand in hands]  # an edited spec file changes the key
    return content_key(
        "batch",
        {"scale": scale, "seed": seed, "hands": specs, "params": used, "schema": SCHEMA_VERSION},
        source_key(str(path)),
    )


def plan_object(name, path, *, scale, seed, hands, params):
    """Run the chain on one mesh, one process: (summary row, trials table or None).

    A :class:`PipelineError` (a refused mesh, ...) gives an ``error`` row with its message."""
    from .checks.protocol import summary as checks_summary
    from .checks.protocol import with_checks
    from .plan import run_chain
    from .trial.protocol import summary

    start = time.perf_counter()
    row = {"object": name, "source": str(path)}
    try:
        artefacts, _ = run_chain(str(path), params, scale=scale, seed=seed, hands=list(hands), simulate=True, workers=1)
    except PipelineError as err:
        return {**row, "status": "error", "reason": str(err), "seconds": time.perf_counter() - start}, None
    trials = artefacts["trials"]
    result, checked = summary(trials), checks_summary(artefacts["check"])
    mat, baseline = result, result["baseline"]  # no trials: NaN rates, not 0 % (pipeline.trial.protocol.trial_rates)

    row.update(
        status="ok",
        reason="",
        samples=len(artefacts["sample"].points),
        medial_spheres=len(artefacts["mat"]),
        reduced_spheres=len(artefacts["classify"]),
        candidates=len(artefacts["candidates"]),
        mat_trials=mat["trials"],
        force_closure_rate=mat["force_closure_rate"],
        mean_epsilon=mat["mean_epsilon"],
        baseline_trials=baseline["trials"],
        baseline_force_closure_rate=baseline["force_closure_rate"],
        physics_success_rate=checked["mat"]["physics_success_rate"],
        baseline_physics_success_rate=checked["baseline"]["physics_success_rate"],
        robust_fc=checked["mat"]["robust_fc"],
        baseline_robust_fc=checked["baseline"]["robust_fc"],
        encompassing_trials=result["encompassing"]["trials"],
        encompassing_force_closure_rate=result["encompassing"]["force_closure_rate"],
        seconds=time.perf_counter() - start,
    )
    if not len(trials):  # no candidate fits a hand: no trials file (an empty table would have other column types)
        return row, None
    trials = with_checks(trials, artefacts["check"])  # unchecked trials: "" and missing values
    return row, trials.assign(object=name)[["object", *trials.columns]]


def summary_frame(rows):
    """Summary rows as a table with the fixed column types of :data:`SUMMARY_COLUMNS` (so that every
    file of ``OUT/objects`` has the same schema, error rows included)."""
    frame = pd.DataFrame(rows).reindex(columns=list(SUMMARY_COLUMNS))
    return frame.astype({column: ("string" if kind is str else kind) for column, kind in SUMMARY_COLUMNS.items()})


def done_keys(out):
    """``{name: key}`` of the objects already done (status ``ok`` or ``error``) under ``out``."""
    folder = Path(out) / "objects"
    if not any(folder.glob("*.parquet")):
        return {}
    done = pd.read_parquet(folder, columns=["object", "key", "status"])
    done = done[done.status.isin(DONE)]
    return dict(zip(done.object, done.key))


def write_object(out, row, trials):
    """Write one object's trials (if any), then its summary row, each atomically."""
    out = Path(out)
    trial_path = out / "trials" / f"{row['object']}.parquet"
    if trials is not None:
        write_table(trial_path, trials)
    else:
        trial_path.unlink(missing_ok=True)  # a stale table of an earlier key
    write_table(out / "objects" / f"{row['object']}.parquet", summary_frame([row]))


def start_ray(address=None, workers=None):
    """Join the cluster at ``address`` (or ``RAY_ADDRESS``), else start an embedded local Ray with
    ``workers`` CPUs (default: every core). Returns the CPUs Ray offers."""
    import ray

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    options = dict(include_dashboard=False, logging_level=logging.WARNING, log_to_driver=False)
    address = address or os.environ.get("RAY_ADDRESS")
    if address:  # other nodes get this package's code; the locked dependencies must be installed there
        ray.init(address=address, runtime_env={"py_modules": [str(Path(__file__).parent)]}, **options)
    else:  # "local": a private instance, even if a `ray start` cluster runs on this machine
        os.environ.setdefault("RAY_AUTH_MODE", "disabled")
        ray.init(address="local", num_cpus=workers or len(os.sched_getaffinity(0)), **options)
    return int(ray.cluster_resources().get("CPU", 1))


def run_batch(
    meshes, out, *, hands, params, scale=1.0, seed=None, address=None, workers=None, progress=None, task=plan_object
):
    """Plan every mesh of ``meshes`` (``[(name, path)]``, see :func:`find_meshes`) into ``out``.

    Objects already done with the same key are skipped without starting Ray. Returns a dict:
    ``skipped``, ``ok``, ``error``, ``failed`` (counts), ``seconds`` and ``ray_start_s``.
    ``progress(text)`` gets a line after each object. ``task`` is what runs per object (same
    signature and result as :func:`plan_object`, which it defaults to).
    """
    seed = params.seed if seed is None else seed
    done = done_keys(out)
    keys = {name: object_key(path, scale=scale, seed=seed, hands=hands, params=params) for name, path in meshes}
    todo = [(name, path) for name, path in meshes if done.get(name) != keys[name]]
    counts = {"skipped": len(meshes) - len(todo), "ok": 0, "error": 0, "failed": 0, "ray_start_s": 0.0}
    start = time.perf_counter()
    if todo:
        counts["ray_start_s"] = _run_on_ray(
            todo,
            keys,
            out,
            counts,
            task,
            hands=hands,
            params=params,
            scale=scale,
            seed=seed,
            address=address,
            workers=workers,
            progress=progress,
        )
    counts["seconds"] = time.perf_counter() - start
    return counts


def _run_on_ray(todo, keys, out, counts, function, *, hands, params, scale, seed, address, workers, progress):
    import ray

    start = time.perf_counter()
    cpus = start_ray(address, workers)
    ray_start = time.perf_counter() - start
    # retried once when its worker dies (segfault, OOM kill); a Python exception is not retried
    task = ray.remote(max_retries=1, retry_exceptions=False)(function)
    pending, queue, begun = {}, iter(todo), time.perf_counter()
    try:
        while True:
            for name, path in queue:
                pending[task.remote(name, path, scale=scale, seed=seed, hands=hands, params=params)] = (name, path)
                if len(pending) >= 2 * cpus:
                    break
            if not pending:
                break
            (ref,), _ = ray.wait(list(pending), num_returns=1)
            name, path = pending.pop(ref)
            try:
                row, trials = ray.get(ref)
            except ray.exceptions.RayError as err:
                row, trials = {"object": name, "source": str(path), "status": "failed", "reason": failure(err)}, None
            write_object(out, {**row, "key": keys[name]}, trials)
            counts[row["status"]] += 1
            if progress:
                finished = counts["ok"] + counts["error"] + counts["failed"]
                rate = 60 * finished / max(time.perf_counter() - begun, 1e-9)
                progress(
                    f"{finished}/{len(todo)} objects: {counts['ok']} ok, {counts['error']} bad mesh, "
                    f"{counts['failed']} failed, {rate:.1f} per minute; {name}: {row['status']}"
                    + (f" ({row['reason']})" if row.get("reason") else "")
                )
    finally:
        ray.shutdown()
    return ray_start


def failure(err):
    """One line saying why a Ray task gave no result: the task's own exception, or what
    happened to its worker."""
    import ray

    if isinstance(err, ray.exceptions.RayTaskError):
        cause = err.cause if err.cause is not None else err
        lines = str(cause).strip().splitlines()
        return f"{type(cause).__name__}: {lines[-1] if lines else ''}"[:500]
    lines = str(err).strip().splitlines()
    retried = (
        " (after one retry)"
        if isinstance(err, (ray.exceptions.WorkerCrashedError, ray.exceptions.OutOfMemoryError))
        else ""
    )
    return f"{type(err).__name__}{retried}: {lines[0] if lines else ''}"[:500]


def read_results(out):
    """``(objects, trials)`` tables of a batch output folder (trials empty if none)."""
    out = Path(out)
    objects = pd.read_parquet(out / "objects")
    trials = pd.read_parquet(out / "trials") if any((out / "trials").glob("*.parquet")) else pd.DataFrame()
    return objects, trials

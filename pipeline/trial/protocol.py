"""The ``simulate`` stage as functions: pick the candidates to test, add the baseline, run the
trials (in worker processes) and summarise them.

Protocol (paper IV): per hand, ``spheres_per_object`` random spheres among those with candidates
for that hand (seeded) and all their candidates; then as many baseline trials; then, as a third
planner, the same for the hand's ``encompassing`` candidates (:mod:`pipeline.geometry.concavity`), if any.

Baseline (the peer planner of Simox's GenericGraspPlanner and OpenRAVE): a random
surface sample (area-uniform, as the samples are), approach along its inward normal, a random
roll about the approach. It runs through the same trial and quality code as the MAT candidates.

Tables
------
trials (``trials.parquet``): one row per trial; ``planner`` (mat | baseline | encompassing), ``hand``,
``candidate_id`` (the candidates table's id; the draw number for the baseline), ``sphere_index``
and ``sphere_class`` (-1 and "surface" for the baseline), ``preshape``, ``grasp_*``,
``approach_*``, ``orient_*`` (the target), ``outcome`` (one of :data:`OUTCOMES`), ``epsilon``,
``contacts``, ``retract_m`` (how far back along -P_d from its placement the hand closed;
negative past it), ``approach_m`` (how far it came on to contact after retreating clear),
``base_*`` (position,
m) and ``base_q*`` (quaternion x, y, z, w) of the hand's URDF base frame as it closed,
``joints`` (closed joint values in the hand's ``limits`` order), ``close_steps``, ``touched``
(names of the links in contact), ``finger_stops`` (per finger: contact, limit, step_cap;
none where the approach missed the object), ``message`` (why a candidate could not be tried,
or that its approach passed the object, if so).

contacts (``contacts.parquet``): one row per contact; ``trial`` (row number in trials),
``link`` (the link's index in the hand model, 0 the base link, the palm), ``x, y, z`` (m) and
``nx, ny, nz`` (the object's outward unit normal).
"""

import collections
import concurrent.futures
import itertools
import os
import pickle
import tempfile
import threading
import time

import numpy as np
import pandas as pd

from .. import seeds
from ..allocator import objects_frozen
from ..arrays import vectors
from ..errors import WorkerError
from ..geometry.mesh_query import grid_distances
from ..pool import context as worker_context
from .engine import (
    OUTCOMES,
    GraspEngine,
    check_simulable,
    kernels_loaded,
    object_mesh,
    run_chunk,
    start_pool_worker,
    start_worker,
    stop_worker,
    trial_settings,
)

#: the trials' ``planner`` values: the MAT candidates, the surface-normal baseline and the
#: candidates encompassing a concavity
PLANNERS = ("mat", "baseline", "encompassing")

# trials advanced together: the closing loop runs as many passes as its slowest trial needs, each
# a fixed cost of numpy calls, so larger chunks share them over more trials (on the duck, one
# core, 2,048 trials: ARMAR-III 5.06 s in chunks of 256, 4.65 s of 512, 4.40 s of 1,024;
# Barrett 4.31, 3.83, 3.51 s), at a little more memory (franka's largest: +0.1 GB at 1,024)
CHUNK = 1024


def select_candidates(candidates, hand_name, spheres, rng, *, encompassing=False):
    """Rows of ``candidates`` for ``hand_name`` on ``spheres`` spheres drawn by the generator
    ``rng`` (all if fewer): of the ``encompassing`` candidates if true, of the others if false."""
    around = (candidates.sphere_class == "encompassing").to_numpy()
    rows = candidates[(candidates.hand == hand_name).to_numpy() & (around == encompassing)]
    indices = np.unique(rows.sphere_index.to_numpy())
    if len(indices) > spheres:
        indices = np.sort(rng.choice(indices, spheres, replace=False))
    return rows[rows.sphere_index.isin(indices)].reset_index(drop=True)


def baseline_candidates(surface, hand, count, rng):
    """``count`` surface-normal candidates for ``hand`` drawn by the generator ``rng``: random
    sample, approach = -normal, random roll; same columns as the candidates table."""
    picks = rng.integers(0, len(surface.points), count)
    approach = -surface.normals[picks]
    # any unit vector orthogonal to the approach, then rolled by a uniform angle
    helper = np.where(np.abs(approach[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    first = np.cross(approach, helper)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    second = np.cross(approach, first)
    roll = rng.uniform(0.0, 2.0 * np.pi, count)[:, None]
    orient = np.cos(roll) * first + np.sin(roll) * second
    grasp = surface.points[picks]
    return pd.DataFrame(
        {
            "hand": hand.name,
            "id": np.arange(count),
            "sphere_index": -1,
            "sphere_class": "surface",
            "diameter_m": np.nan,
            "preshape": hand.default_preshape,
            **{f"grasp_{axis}": grasp[:, k] for k, axis in enumerate("xyz")},
            **{f"approach_{axis}": approach[:, k] for k, axis in enumerate("xyz")},
            **{f"orient_{axis}": orient[:, k] for k, axis in enumerate("xyz")},
        }
    )


def chunks(hands, lengths, workers=1):
    """The chunks of the trials of tables of ``lengths`` rows, numbered through the tables in
    order, those of one hand (the tables' ``hands`` numbers) together: (hand, trial numbers) each,
    :data:`CHUNK` trials at most. Each hand's trials in a multiple of ``workers`` chunks, so that
    every chunk is as large as the batch allows (the engine's per-pass cost is shared by its
    trials; a hand's small tables add no chunks of their own) and, with several workers, a sample
    of them all (the processes end together whatever the order of the trials' costs).

    The hand's ``k``-th trial goes to chunk ``s(k) mod count``, ``s(k)`` the sum of ``k``'s digits
    in base ``2 count``: every ``count`` trials in a row give one to each chunk, as ``k mod count``
    would, and rows of a kind that recurs every 2 or 4 spread evenly over the chunks. A rim
    sphere's two candidates, P_o then -P_o, are such rows: ``k mod count`` gave each chunk one
    of the two with an even count, and with ARMAR-III on the duck's default stage one chunk cost
    10 % more than the other (on one core, 0.907 against 0.824 s)."""
    hands, lengths = np.asarray(hands, np.int64), np.asarray(lengths, np.int64)
    first = np.cumsum(lengths) - lengths
    for hand in dict.fromkeys(hands.tolist()):
        tables = np.flatnonzero(hands == hand)
        trials = np.concatenate([np.arange(first[table], first[table] + lengths[table]) for table in tables])
        count = workers * -(-len(trials) // (workers * CHUNK))
        chunk_of = _digit_sums(np.arange(len(trials)), 2 * count) % count
        for chunk in range(min(count, len(trials))):
            yield hand, trials[chunk_of == chunk]


class TrialPool:
    """Trial worker processes that :func:`run_trials`' calls share, from the first call that
    needs them to :meth:`close` (or the end of a ``with`` block): a call with one skips starting
    its workers, and their first trials' one-off costs (numba's, numpy's and open3d's first calls,
    the pages a fresh process writes), about 0.1 s a worker. As many processes as the most any call
    asked for; each holds the engines of the last call it ran chunks of until the next.
    For a process that runs trials call after call (an ablation, the bench); one call's workers
    are its own, closed after it."""

    def __init__(self):
        self._executor, self._size = None, 0

    def executor(self, size):
        """The pool's ``concurrent.futures`` executor, with ``size`` worker processes or more."""
        if size > self._size:
            self.close()
            self._executor, self._size = _executor(size), size
        return self._executor

    def close(self):
        """End the worker processes (a call's later use starts new ones)."""
        if self._executor is not None:
            self._executor.shutdown(cancel_futures=True)
        self._executor, self._size = None, 0

    def __enter__(self):
        return self

    def __exit__(self, *_):
        self.close()


def _executor(size):
    """A pool of ``size`` trial worker processes (:func:`pipeline.trial.engine.start_pool_worker`),
    forked from the server of :mod:`pipeline.pool` as its tasks need them."""
    return concurrent.futures.ProcessPoolExecutor(size, worker_context(), initializer=start_pool_worker)


#: numbers the calls whose engines a pool's workers load (a file's path may come again)
_CALLS = itertools.count()


def _digit_sums(numbers, base):
    """(n,) the sums of the digits of the (n,) non-negative int ``numbers`` written in ``base``."""
    numbers, sums = np.array(numbers, np.int64), np.zeros(len(numbers), np.int64)
    while numbers.any():
        sums += numbers % base
        numbers //= base
    return sums


# the caller's objects (its libraries', its tables) out of the collector's full passes, which the
# trials' own objects set off: each walked them all, 0.13-0.15 s in the bench's process
@objects_frozen()
def run_trials(surface, hands, tables, settings, *, workers=1, pool=None, progress=None, timeline=None):
    """One trial per row of each table (candidate columns).

    Parameters
    ----------
    surface : SurfaceSamples
    hands : list of Hand
    tables : list of (int, pandas.DataFrame)
        Each table with the number of its hand in ``hands``; a ``mu`` column, if any, is each
        trial's friction coefficient for its grading (the robust check's noisy copies), else
        the settings' ``mu``.
    settings : SimulateParams or None
        How the trials run (:class:`pipeline.trial.engine.GraspEngine`'s ``settings``).
    workers : int
        Processes, this one included: it builds the engines (one object mesh for every hand),
        then runs chunks itself, while ``workers - 1`` worker processes (:mod:`pipeline.pool`),
        started first, wait for a copy of them and take theirs, each the next chunk left; the
        first worker computes the object's distance grid meanwhile, the engines' costly part.
        A process that has run no trial yet (a stage's) runs none: ``workers`` workers take
        every chunk. Results do not depend on it.
    pool : TrialPool, optional
        Worker processes kept between calls; without it the call starts its own and ends them.
    progress : callable(int, int), optional
        Called with the number of trials just finished and the total.
    timeline : list, optional
        Where the call's time went, appended as (step, process, start, end) spans in
        ``time.perf_counter`` seconds (process 0 this one, 1 to ``workers - 1`` the workers):
        ``start workers`` (the threads that fork them started), ``set-up`` (the engines built), ``ship``
        (their copy written for the workers), ``chunk`` (each chunk's trials, where they ran),
        ``results`` (a worker's chunk ended to its results here), ``call`` (the whole call).

    Returns
    -------
    list (per table) of lists of TrialResult, in table order
    """
    called = time.perf_counter()
    spans = [] if timeline is None else timeline
    # every table's candidates in one set of arrays: a chunk's go to a worker as a few arrays
    # (as (P_g, P_d, P_o) tuples, 1,024 took 0.014 s to pickle here and 0.008 s to load there)
    lengths = [len(table) for _, table in tables]
    targets = [
        np.concatenate([vectors(table, name) for _, table in tables]) if tables else np.zeros((0, 3))
        for name in ("grasp", "approach", "orient")
    ]
    preshapes = [name for _, table in tables for name in table.preshape]
    parts = list(chunks([number for number, _ in tables], lengths, workers))
    done, total, lock = [None] * len(parts), sum(lengths), threading.Lock()
    left = collections.deque(range(len(parts)))

    def take():
        with lock:
            return left.popleft() if left else None

    def finish(number, process, results, start, end):
        with lock:
            done[number] = results
            spans.append(("chunk", process, start, end))
            if process:
                spans.append(("results", process, end, time.perf_counter()))
            if progress:
                progress(len(results), total)

    def chunk_of(number):
        hand, trials = parts[number]
        return hand, *(values[trials] for values in targets), [preshapes[trial] for trial in trials], mus[trials]

    settings = trial_settings(settings)
    mus = np.concatenate(
        [np.zeros(0)]
        + [
            table["mu"].to_numpy(np.float64) if "mu" in table.columns else np.full(len(table), settings.mu)
            for _, table in tables
        ]
    )
    used = sorted({number for (number, _), length in zip(tables, lengths) if length})
    feeders, failed = [], []
    # the object's distance grid is most of an engine's set-up: built once, by the first worker
    # (on every core) while this process builds the rest, or here without workers. The first
    # worker's thread submits its task: a submit waits until the fork server has done its
    # imports, about 2 s after a stage's start (a stage's 2-core call waited 0.99 s for it here,
    # before its set-up), and this process builds the rest meanwhile
    grid = concurrent.futures.Future()  # the grid's task, once submitted
    # a process that has run no trial loads the engine's compiled kernels in its first chunk
    # (a stage's ARMAR-III trials on the duck: 19 kernels, 0.56 s; its chunk took 1.62-1.80 s,
    # the worker's 1.19-1.26 s), which the workers have from their server: it leaves its share
    # of the chunks to one more worker
    runs_chunks = workers == 1 or kernels_loaded()
    helpers = min(workers, len(parts)) - int(runs_chunks)
    # the worker processes start (or are the pool's) while this one builds the engines; their
    # chunks go once the engines are ``shipped``: pickled to a file (a pipe would move them 64 KB
    # a write, each waiting for this thread to let go of the interpreter: a worker started 0.06 s
    # late), which each worker loads at its first chunk
    shipped, copy = threading.Event(), None  # copy: (the file's path, this call's number)
    executor = None if helpers <= 0 else pool.executor(helpers) if pool else _executor(helpers)

    def ship(engines):
        nonlocal copy
        handle, path = tempfile.mkstemp(prefix="engines-", suffix=".pickle")
        with os.fdopen(handle, "wb") as file:
            pickle.dump(engines, file, pickle.HIGHEST_PROTOCOL)
        copy = (path, next(_CALLS))
        shipped.set()

    # one thread per worker process forks it (its first submit) while this one builds the
    # engines, then keeps it busy, chunk after chunk: the fork is a wait on the fork server
    # (0.006-0.017 s) with the interpreter lock let go, and a chunk's candidates, a few arrays,
    # pickle at once
    def feed(number, process):
        try:
            if process == 1:  # the grid's task first, so that a worker takes it before any chunk
                grid.set_result(
                    executor.submit(grid_distances, surface.vertices, surface.faces, settings.grid_cells)
                    if used
                    else None
                )
            else:
                grid.result()
                # a submit forks a worker when none is idle: this one's now, while the engines
                # are built, rather than with its first chunk (a fork and start, 0.05 s)
                executor.submit(os.getpid).result()
            shipped.wait()
            while copy is not None and number is not None:  # no copy: the engines' build failed
                finish(number, process, *executor.submit(run_chunk, copy, *chunk_of(number)).result())
                number = take()
        except BaseException as error:  # noqa: BLE001 (raised again in the caller's thread)
            if not grid.done():
                grid.set_exception(error)
            failed.append(error)
            with lock:
                left.clear()

    try:
        for process in range(1, helpers + 1):
            feeders.append(threading.Thread(target=feed, args=(take(), process), daemon=True))
            feeders[-1].start()
        forked = time.perf_counter()
        spans.append(("start workers", 0, called, forked))
        try:
            mesh = (
                object_mesh(surface, settings, (lambda: grid.result().result()) if executor else None) if used else None
            )
        except concurrent.futures.BrokenExecutor as error:
            failed.append(error)
            raise _worker_error(surface, total, workers) from error
        engines = {number: GraspEngine(surface, hands[number], settings, mesh=mesh) for number in used}
        built = time.perf_counter()
        spans.append(("set-up", 0, forked, built))
        if helpers > 0:
            mesh.threads = 1  # a core per process: open3d's threads would only contend for them
            ship(engines)
            spans.append(("ship", 0, built, time.perf_counter()))
        start_worker(engines)
        try:
            while runs_chunks and (number := take()) is not None:
                finish(number, 0, *run_chunk(None, *chunk_of(number)))
        except BaseException:
            with lock:
                left.clear()
            raise
        finally:
            stop_worker()
            for feeder in feeders:
                feeder.join()
    finally:
        shipped.set()  # the feeders go on if the engines' build failed, with nothing to send
        broken = any(isinstance(error, concurrent.futures.BrokenExecutor) for error in failed)
        if pool and broken:
            pool.close()
        if executor and not pool:
            # the workers' exit (0.015 s) and the removal of their copy go on in the background
            threading.Thread(target=_close_pool, args=(executor, copy), name="close trial pool").start()
        elif copy:
            os.unlink(copy[0])  # every chunk has run: the workers have loaded it
    if failed:
        if isinstance(failed[0], concurrent.futures.BrokenExecutor):
            raise _worker_error(surface, total, workers) from failed[0]
        raise failed[0]
    results = [None] * total
    for (_, trials), found in zip(parts, done):
        for trial, result in zip(trials, found):
            results[trial] = result
    spans.append(("call", 0, called, time.perf_counter()))
    return [results[first : first + length] for first, length in zip(np.cumsum(lengths) - lengths, lengths)]


def _worker_error(surface, total, workers):
    """The :class:`WorkerError` of a trial worker that ended abruptly."""
    return WorkerError(
        f"{surface.source}: a trial worker process ended abruptly (killed by a signal, or by the system for memory) "
        f"with {total} trials to run on {workers} processes; rerun with fewer workers (params.yaml's "
        f"simulate.workers, or --workers): each holds the object's mesh and a chunk of up to {CHUNK} trials"
    )


def _close_pool(executor, copy):
    """Wait for ``executor``'s workers to end, then remove the file of ``copy`` (if any) they
    read their engines from."""
    executor.shutdown(cancel_futures=True)
    if copy:
        os.unlink(copy[0])


def trial_tables(surface, candidates, hands, *, spheres_per_object, baseline_trials, seed=0):
    """The tables of candidates a ``simulate`` stage tries (the module docstring's protocol):
    (planner, hand number in ``hands``, table) for each hand's MAT candidates, its baseline and,
    if any, its encompassing candidates; arguments as :func:`simulate`'s."""
    jobs = []
    for number, hand in enumerate(hands):
        # fresh streams for every hand: a hand's trials do not depend on the other hands run with it
        mat = select_candidates(candidates, hand.name, spheres_per_object, seeds.trial_spheres(seed))
        count = len(mat) if baseline_trials < 0 else baseline_trials
        baseline = baseline_candidates(surface, hand, count, seeds.baseline(seed))
        jobs += [("mat", number, mat), ("baseline", number, baseline)]
        encompassing = select_candidates(
            candidates, hand.name, spheres_per_object, seeds.trial_spheres(seed), encompassing=True
        )
        if len(encompassing):
            jobs.append(("encompassing", number, encompassing))
    return jobs


def simulate(
    surface, candidates, hands, *, spheres_per_object, baseline_trials, seed=0, workers=1, settings=None, progress=None
):
    """Trials of the selected MAT candidates and the baseline for every hand.

    Parameters
    ----------
    surface : SurfaceSamples
    candidates : pandas.DataFrame
        The candidates table.
    hands : list of Hand
    spheres_per_object : int
    baseline_trials : int
        Baseline trials per hand; -1 = as many as that hand's MAT trials, 0 = none.
    seed : int
    workers : int
    settings : SimulateParams, optional
        How the trials run (the defaults when None).
    progress : callable(int, int), optional
        Called with the number of trials just finished and the total.

    Returns
    -------
    trials, contacts : pandas.DataFrame (see the module docstring)
    """
    check_simulable(surface)
    jobs = trial_tables(
        surface, candidates, hands, spheres_per_object=spheres_per_object, baseline_trials=baseline_trials, seed=seed
    )
    results = run_trials(
        surface,
        hands,
        [(number, table) for _, number, table in jobs],
        settings,
        workers=workers,
        progress=progress,
    )
    return _tables([(planner, hands[number], table, result) for (planner, number, table), result in zip(jobs, results)])


def _tables(blocks):
    trial_rows, contact_rows, offset = [], [], 0
    for planner, hand, table, results in blocks:
        frame = table[
            ["id", "sphere_index", "sphere_class", "preshape"]
            + [f"{prefix}_{axis}" for prefix in ("grasp", "approach", "orient") for axis in "xyz"]
        ].copy()
        frame = frame.rename(columns={"id": "candidate_id"})
        frame["sphere_class"] = frame.sphere_class.astype(str)
        frame.insert(0, "hand", hand.name)
        frame.insert(0, "planner", planner)
        frame["outcome"] = [result.outcome for result in results]
        frame["epsilon"] = [result.epsilon for result in results]
        frame["contacts"] = [len(result.contact_points) for result in results]
        frame["retract_m"] = [result.retract_m for result in results]
        frame["approach_m"] = [result.approach_m for result in results]
        base = np.array([result.base_position for result in results]).reshape(-1, 3)
        quaternion = np.array([result.base_orientation for result in results]).reshape(-1, 4)
        for k, axis in enumerate("xyz"):
            frame[f"base_{axis}"] = base[:, k]
        for k, axis in enumerate("xyzw"):
            frame[f"base_q{axis}"] = quaternion[:, k]
        frame["joints"] = [list(result.joint_positions) for result in results]
        frame["close_steps"] = np.array([result.close_steps for result in results], np.int64)
        frame["touched"] = [list(result.touched) for result in results]
        frame["finger_stops"] = [list(result.finger_stops) for result in results]
        frame["message"] = [result.message for result in results]
        trial_rows.append(frame)
        for number, result in enumerate(results):
            if len(result.contact_points):
                contact_rows.append(
                    pd.DataFrame(
                        {
                            "trial": offset + number,
                            "link": result.contact_links,
                            **{axis: result.contact_points[:, k] for k, axis in enumerate("xyz")},
                            **{f"n{axis}": result.contact_normals[:, k] for k, axis in enumerate("xyz")},
                        }
                    )
                )
        offset += len(results)
    trials = pd.concat(trial_rows, ignore_index=True) if trial_rows else pd.DataFrame()
    if len(trials):
        trials["outcome"] = pd.Categorical(trials.outcome, categories=OUTCOMES)
    contacts = (
        pd.concat(contact_rows, ignore_index=True)
        if contact_rows
        else pd.DataFrame(
            {
                "trial": pd.Series(dtype=np.int64),
                "link": pd.Series(dtype=np.int64),
                **{name: pd.Series(dtype=float) for name in ("x", "y", "z", "nx", "ny", "nz")},
            }
        )
    )
    return trials, contacts


def trial_rates(trials):
    """``trials``, ``force_closure_rate``, ``mean_epsilon`` (over force-closure trials) and
    ``outcomes`` counts of a trials table (or a slice of it). A rate or mean of no trials is NaN
    (null in JSON), never 0."""
    closed = trials.outcome == "force_closure"
    return {
        "trials": int(len(trials)),
        "force_closure_rate": float(closed.mean()) if len(trials) else float("nan"),
        "mean_epsilon": float(trials.epsilon[closed].mean()) if closed.any() else float("nan"),
        "outcomes": {outcome: int((trials.outcome == outcome).sum()) for outcome in OUTCOMES},
    }


def summary(trials):
    """The JSON-ready results: MAT totals at the top level, ``baseline`` and ``encompassing``
    beside them and ``per_hand`` for every planner."""
    planners = {planner: trials[trials.planner == planner] for planner in PLANNERS}
    return {
        **trial_rates(planners["mat"]),
        **{planner: trial_rates(planners[planner]) for planner in PLANNERS[1:]},
        "per_hand": {
            hand: {planner: trial_rates(rows[rows.hand == hand]) for planner, rows in planners.items()}
            for hand in sorted(trials.hand.unique())
        },
    }

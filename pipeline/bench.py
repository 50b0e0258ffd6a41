"""Benchmarks: medial_axis + mat against the Voronoi poles, and classify + candidates per sphere.

Radius error is measured against the analytic shape: for every medial sphere,
``|r - d(X)|`` where ``d(X)`` is the exact distance from its centre to the true surface,
as a fraction of the shape's half thickness (box: 0.01 m; capsule: its radius 0.02 m).
"""

import contextlib
import json
import os
import time
import tracemalloc
from collections import Counter, defaultdict

import numpy as np
import pandas as pd

from .arrays import vectors
from .artefacts import atomic_write
from .geometry import sphere_grid
from .geometry.candidates import generate, generate_for_hands
from .geometry.mat import reconstruct
from .geometry.medial_axis import medial_axis
from .geometry.sampling import sample_object
from .geometry.symmetry import classify
from .hands.spec import HANDS
from .params import CandidatesParams, ClassifyParams, MatParams, MedialAxisParams, Params, SampleParams, SimulateParams
from .pool import default_workers
from .trial.engine import GraspEngine
from .trial.protocol import CHUNK, TrialPool, chunks, run_trials, trial_tables

#: run_trials' batches in the trial bench: a small and a median default simulate stage (make
#: run's run up to 3,276 trials, median about 2,000)
TRIAL_BATCHES = (512, 2048)
#: the label of the trial table's third batch: a default ``simulate`` stage's tables on the duck
STAGE_BATCH = "stage"

BOX_HALF = np.array([0.05, 0.03, 0.01])
CAPSULE_RADIUS, CAPSULE_HALF_LENGTH = 0.02, 0.05

SHAPES = {
    "box": (dict(extents=list(2 * BOX_HALF)), lambda c: np.min(BOX_HALF - np.abs(c), axis=1), BOX_HALF[2]),
    "capsule": (
        dict(radius=CAPSULE_RADIUS, height=2 * CAPSULE_HALF_LENGTH),
        lambda c: (
            CAPSULE_RADIUS - np.hypot(np.hypot(c[:, 0], c[:, 1]), np.maximum(np.abs(c[:, 2]) - CAPSULE_HALF_LENGTH, 0))
        ),
        CAPSULE_RADIUS,
    ),
}


def _run(surface, method):
    axis = medial_axis(surface, **{**vars(MedialAxisParams()), "method": method})
    return reconstruct(surface, axis, **vars(MatParams()))


def _measure(surface, method, repeats):
    """Median wall time of ``repeats`` untraced runs, then one traced run for the peak memory."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        spheres = _run(surface, method)
        times.append(time.perf_counter() - start)
    tracemalloc.start()
    _run(surface, method)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return float(np.median(times)), peak, spheres


def run_bench(
    *, sizes=(20000, 100000, 200000), repeats=3, json_path=None, trials=512, reference_trials=60, only=None, out=print
):
    """Print (and optionally save) the benchmark tables (``only``: one of medial, symmetry,
    trials, checks, stages, evaluate, recording, batch, run); returns {table: rows}."""
    tables = {}
    if only in (None, "medial"):
        tables["medial"] = run_medial_bench(sizes=sizes, repeats=repeats, out=out)
        out("")
    if only in (None, "symmetry"):
        tables["symmetry"] = run_symmetry_bench(repeats=repeats, out=out)
        out("")
    if only in (None, "trials"):
        tables["trials"] = run_trial_bench(trials=trials, reference_trials=reference_trials, repeats=repeats, out=out)
        out("")
    if only in (None, "checks"):
        tables["checks"] = run_check_bench(out=out)
        out("")
    if only in (None, "stages"):
        tables["stages"] = run_stage_bench(repeats=repeats, out=out)
        out("")
    if only in (None, "evaluate"):
        tables["evaluate"] = run_evaluate_bench(out=out)
        out("")
    if only in (None, "recording"):
        tables["recording"] = run_recording_bench(repeats=repeats, out=out)
        out("")
    if only in (None, "batch"):
        tables["batch"] = run_batch_bench(out=out)
        out("")
    if only in (None, "run"):
        tables["run"] = run_occupancy_bench(out=out)
    if json_path:
        text = json.dumps({"repeats": repeats, **tables}, indent=2).encode()
        atomic_write(json_path, lambda stream: stream.write(text))
    return tables


def run_medial_bench(*, sizes=(20000, 100000, 200000), repeats=3, out=print):
    """medial_axis + mat, both methods, on a box and a capsule; returns the rows."""
    rows = []
    out(
        f"{'shape':8} {'samples':>8} {'method':15} {'median s':>9} {'peak MiB':>9} {'spheres':>8} "
        f"{'radius err (median, p95)':>26}"
    )
    for shape, (keywords, true_distance, scale) in SHAPES.items():
        for count in sizes:
            surface = sample_object(
                f"primitive:{shape}",
                shape=keywords,
                rng=np.random.default_rng(0),
                source_key=shape,
                **{**vars(SampleParams()), "count": count},
            )
            for method in ("shrinking_ball", "voronoi_poles"):
                seconds, peak, spheres = _measure(surface, method, repeats)
                error = np.abs(spheres.radii - true_distance(spheres.centers)) / scale
                row = dict(
                    shape=shape,
                    samples=count,
                    method=method,
                    median_s=round(seconds, 4),
                    peak_mib=round(peak / 2**20, 1),
                    spheres=len(spheres),
                    radius_error_median=float(np.median(error)),
                    radius_error_p95=float(np.percentile(error, 95)),
                )
                rows.append(row)
                out(
                    f"{shape:8} {count:8d} {method:15} {seconds:9.3f} {row['peak_mib']:9.1f} {len(spheres):8d} "
                    f"{row['radius_error_median']:12.2e} {row['radius_error_p95']:12.2e}"
                )
            masb, poles = rows[-2], rows[-1]
            out(
                f"{'':8} {'':8} ratio poles/masb: time {poles['median_s'] / masb['median_s']:.1f}x, "
                f"median radius error {poles['radius_error_median'] / max(masb['radius_error_median'], 1e-18):.1f}x"
            )
    return rows


def run_symmetry_bench(*, sphere_counts=(10000, 100000), repeats=3, out=print):
    """Time classify + candidates per sphere on the grid of medial spheres of a plate and a capsule.

    The sample count is raised until the grid holds about the asked number of spheres.
    Returns the rows.
    """
    rows = []
    out(f"{'shape':8} {'spheres':>8} {'selected':>8} {'median s':>9} {'us/sphere':>10} {'candidates':>10}")
    shapes = {"plate": dict(extents=[0.10, 0.10, 0.006]), "box": dict(extents=list(2 * BOX_HALF))}
    hands = [HANDS[name] for name in CandidatesParams().hands]
    for shape, keywords in shapes.items():
        for wanted in sphere_counts:
            surface = sample_object(
                f"primitive:{shape}",
                shape=keywords,
                rng=np.random.default_rng(0),
                source_key=shape,
                **{**vars(SampleParams()), "count": int(wanted * 1.03)},
            )
            grid = sphere_grid.build(
                reconstruct(surface, medial_axis(surface, **vars(MedialAxisParams())), **vars(MatParams()))
            )
            times = []
            for _ in range(repeats):
                start = time.perf_counter()
                symmetry = classify(grid, **vars(ClassifyParams()))
                table = generate_for_hands(symmetry, None, hands)
                times.append(time.perf_counter() - start)
            seconds = float(np.median(times))
            row = dict(
                shape=shape,
                spheres=len(grid),
                selected=len(symmetry),
                median_s=round(seconds, 4),
                us_per_sphere=round(1e6 * seconds / len(grid), 2),
                candidates=len(table),
            )
            rows.append(row)
            out(
                f"{shape:8} {len(grid):8d} {len(symmetry):8d} {seconds:9.3f} {row['us_per_sphere']:10.2f} "
                f"{len(table):10d}"
            )
    out("paper: 10-100 ms per sphere (Python, 2011); target <= 10 us per sphere")
    return rows


def trial_bench_chain():
    """The chain (:func:`pipeline.plan.run_chain`, default params, seed 0) on the duck of
    pybullet_data, 10 cm long, with each triangle split in four (16,848 triangles): its
    artefacts up to the candidates, and the triangle count."""
    import tempfile
    from pathlib import Path

    from .geometry.objects import load_source
    from .plan import run_chain

    _, mesh = load_source("pybullet:duck.obj", scale=0.06)
    mesh = mesh.subdivide()
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "duck.ply"
        mesh.export(path)
        artefacts, _ = run_chain(str(path), Params(), seed=0)
    return artefacts, len(mesh.faces)


def drawn_first(candidates, trials):
    """The rows of ``candidates``: ``trials`` of them drawn at random first, then the others in
    a random order (both seeded), renumbered."""
    drawn = candidates.sample(min(trials, len(candidates)), random_state=0)
    others = candidates.drop(index=drawn.index).sample(frac=1, random_state=0)
    return pd.concat([drawn, others], ignore_index=True)


def candidate_targets(table):
    """The targets of a table of candidates as :meth:`GraspEngine.run` takes them: grasp,
    approach, orient (n, 3) and the preshapes (n,)."""
    return vectors(table, "grasp"), vectors(table, "approach"), vectors(table, "orient"), list(table.preshape)


def _warm_engine(surface, candidates, hand, trials, settings):
    """``trials`` random rows of ``hand``'s MAT ``candidates`` (seeded: the first of
    :func:`drawn_first`), their targets (grasp, approach, orient, preshapes) and an engine that
    has run two of them, its exact queries on one thread (the tables time it on one core)."""
    table = drawn_first(candidates, trials).iloc[:trials]
    targets = candidate_targets(table)
    engine = GraspEngine(surface, hand, settings)
    # open3d's queries would otherwise take every CPU the process may use: before 2026-12-07,
    # session 61, the "one core" engine rates did, and the chunks timed under one_core ran two
    # query threads on its one CPU
    engine.mesh.threads = 1
    # numba loads its compiled kernels on their first call (about 0.3 s a process, once): part
    # of the start-up (measured through the pool in the trial table), not of the trials
    engine.run(*(values[:2] for values in targets))
    return table, targets, engine


def _trial_trace(result):
    """One trial in a line, to trace a disagreement: outcome, epsilon, where the hand closed,
    the finger stops and the links that touched."""
    return (
        f"{result.outcome} eps {result.epsilon:.3f} retract {result.retract_m * 1000:.1f} mm "
        f"stops {','.join(result.finger_stops)} touched {','.join(sorted(result.touched)) or '-'}"
    )


@contextlib.contextmanager
def one_core():
    """Every thread of this process (open3d's and numba's pools included) held to one CPU while
    inside, as on a one-core machine; the affinity it had afterwards."""
    before = os.sched_getaffinity(0)

    def hold(cpus):
        for task in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(task), cpus)
            except OSError:  # a thread that ended meanwhile
                pass

    hold({min(before)})
    try:
        yield
    finally:
        hold(before)


def interleaved_seconds(runs, rounds, clock=time.perf_counter, own=()):
    """Seconds of each of ``runs`` ({name: callable}), ``rounds`` times, one of each per round in
    turn, so that the machine's drift (a noisy neighbour, a slower phase) reaches every run alike
    and their ratios can be taken round by round: {name: (rounds,) float array}. The runs named
    in ``own`` return seconds of their own (a float or a (k,) array: :func:`at_once`'s), which
    time them instead: their values are (rounds,) or (rounds, k)."""
    seconds = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            start = clock()
            found = run()
            seconds[name].append(found if name in own else clock() - start)
    return {name: np.array(values) for name, values in seconds.items()}


def at_once(calls, cpus, runs=1):
    """Runs ``calls`` (callables) at the same time, each in a process forked from this one (a
    copy sharing its memory until written) and held to its CPU of ``cpus``, ``runs`` times,
    every copy released together each time once all are ready. Returns (runs, len(calls))
    seconds, each run's own: what the machine gives the same work on several cores with no pool
    in between; a copy's first run also copies each page it writes (shared with this process
    until then), its later ones do not. Raises RuntimeError, with the child's error, where a
    call fails."""
    children = []  # (pid, the copy's result pipe, the write end of its release pipe)
    failed = None
    try:
        for call, cpu in zip(calls, cpus, strict=True):
            read, write = os.pipe()
            release, go = os.pipe()
            pid = os.fork()
            if pid == 0:  # the child: only os._exit leaves it (no atexit, no parent's buffers)
                status = 1
                try:
                    # the parent's ends, the earlier copies' included: a parent that fails before
                    # releasing a copy ends its wait (EOF)
                    for end in [read, go, *(end for _, pipe, go_end in children for end in (pipe.fileno(), go_end))]:
                        os.close(end)
                    os.sched_setaffinity(0, {cpu})
                    seconds = []
                    for _ in range(runs):
                        os.write(write, b"r")  # ready: the parent releases all once all are
                        if not os.read(release, 1):
                            raise RuntimeError("the parent ended before releasing this copy")
                        start = time.perf_counter()
                        call()
                        seconds.append(time.perf_counter() - start)
                    os.write(write, " ".join(map(repr, seconds)).encode())
                    status = 0
                except BaseException as error:  # noqa: BLE001 (reported to the parent)
                    os.write(write, f"error: {type(error).__name__}: {error}".encode())
                finally:
                    os._exit(status)
            os.close(write)
            os.close(release)
            children.append((pid, os.fdopen(read, "rb"), go))
        for _ in range(runs):
            for _, pipe, _ in children:
                if (word := pipe.read(1)) != b"r":  # an error's first letter, or none: it ended
                    failed = (word + pipe.read()).decode() or "it ended with no word"
                    break
            if failed:
                break
            for _, _, go in children:
                os.write(go, b"x")
        found = [pipe.read().decode() for _, pipe, _ in children] if not failed else []
    finally:
        for _, _, go in children:  # copies still waiting for a release end their wait (EOF)
            os.close(go)
        for pid, pipe, _ in children:
            os.waitpid(pid, 0)
            pipe.close()
    failed = failed or next((message for message in found if message.startswith("error")), None)
    if failed:
        raise RuntimeError(f"a call run at once failed: {failed}")
    return np.array([[float(value) for value in message.split()] for message in found]).T


def timeline_parts(timeline):
    """Seconds of a :func:`run_trials` call's steps from its ``timeline``: ``start`` (starting the
    threads that fork the workers), ``set-up`` (the engines), ``ship`` (their copy for the workers), ``caller`` and
    ``workers`` (the trials of the caller's chunks; of the busiest worker's), ``lag`` (that
    worker's first chunk's start after the caller's first), ``results`` (its chunks' ends to
    their results in the caller) and ``after`` (the last of those to the call's end)."""
    spans = defaultdict(list)
    for step, process, start, end in timeline:
        spans[step, process].append((start, end))
    (call,) = spans["call", 0]
    last = max(end for (step, _), found in spans.items() if step != "call" for _, end in found)

    def busy(step, process):
        return sum(end - start for start, end in spans[step, process])

    def first(process):
        return min(start for start, _ in spans["chunk", process])

    workers = {process for step, process in spans if step == "chunk" and process}
    busiest = max(workers, key=lambda process: busy("chunk", process), default=None)  # None: no steps
    return {
        "start": busy("start workers", 0),
        "set-up": busy("set-up", 0),
        "ship": busy("ship", 0),
        "caller": busy("chunk", 0),
        "workers": busy("chunk", busiest),
        "lag": first(busiest) - first(0) if workers else 0.0,
        "results": busy("results", busiest),
        "after": call[1] - last,
    }


def free_workers_ratio(one_core, all_cores, cores):
    """The ratio of a :func:`run_trials` call on ``cores`` cores to one on one core had its
    workers cost nothing (no fork, no copy, no trip back, each process's share of the trials
    taking its share of one core's time), from their :func:`timeline_parts`: one core's set-up
    and trials over all cores' set-up and one core's trials shared."""
    return (one_core["set-up"] + one_core["caller"]) / (all_cores["set-up"] + one_core["caller"] / cores)


def _chunk_runs(engine, targets, workers):
    """Calls of ``engine`` (set up, in this process) on the candidates ``targets`` (grasp,
    approach, orient (n, 3), preshapes (n,)): {"whole": all of them in one run, 0: the first of
    the chunks :func:`pipeline.trial.protocol.run_trials` deals them to on ``workers``
    processes, 1: ...}."""
    count = len(targets[0])

    def run(rows):
        picked = (*(values[rows] for values in targets[:3]), [targets[3][row] for row in rows])
        return lambda: engine.run(*picked)

    parts = {number: run(rows) for number, (_, rows) in enumerate(chunks([0], [count], workers))}
    return {"whole": run(np.arange(count)), **parts}


def chunks_seconds(engine, targets, rounds, workers, cpus=None):
    """Seconds of :func:`_chunk_runs`, each alone, in ``rounds`` interleaved rounds
    (:func:`interleaved_seconds`): {"whole": (rounds,) float array, 0: the first chunk's, 1: ...}.
    With ``cpus`` (one per chunk), in the same rounds, the chunks in forked copies of this
    process (:func:`at_once`), ``"forked"`` one after another and ``"at once"`` together, each
    on its CPU and run twice (a fresh copy's first run, then its second): (rounds, 2, chunks)
    arrays; the whole run then runs once more here, untimed, before the next round's."""
    runs = _chunk_runs(engine, targets, workers)
    if cpus is not None:
        parts = [run for name, run in runs.items() if name != "whole"]
        cpus = [cpus[number % len(cpus)] for number in range(len(parts))]
        whole = runs["whole"]

        def together():
            seconds = at_once(parts, cpus, 2)
            # a fork leaves this process's pages write-protected, and the next run here paid a
            # fault on each page it wrote first: the next round's whole run, timed (the jaw's 512
            # trials: 0.69 s after a fork, 0.60 s without, more than splitting them costs)
            whole()
            return seconds

        runs["forked"] = lambda: np.concatenate([at_once([part], [cpu], 2) for part, cpu in zip(parts, cpus)], axis=1)
        runs["at once"] = together
    return interleaved_seconds(runs, rounds, own=("forked", "at once"))


def together_factor(alone, together):
    """How much longer the longest of a batch's chunks took in one way than in another, from
    (rounds, chunks) seconds: the median of the rounds' ratios of their longest. With
    :func:`chunks_seconds`' second runs ``"at once"`` over ``"forked"`` (alone): 1 where the
    cores do not slow each other."""
    return float(np.median(together.max(axis=1) / alone.max(axis=1)))


def own_time_parts(stats):
    """Seconds of a profile (a ``pstats.Stats``) by where each function's own time went:
    {"kernels": this process's compiled kernels (numba dispatchers, looked up by module file
    and name), "open3d": open3d's queries, "calls": the rest, the Python and numpy calls around
    them}."""
    import sys

    from numba.core.dispatcher import Dispatcher

    modules = {getattr(module, "__file__", None): module for module in list(sys.modules.values())}
    found = dict.fromkeys(("kernels", "open3d", "calls"), 0.0)
    for (filename, _, function), (_, _, own, _, _) in stats.stats.items():
        if isinstance(getattr(modules.get(filename), function, None), Dispatcher):
            found["kernels"] += own
        elif "open3d" in function:
            found["open3d"] += own
        else:
            found["calls"] += own
    return found


def chunks_own_time(engine, targets, workers):
    """:func:`own_time_parts` of :func:`_chunk_runs`, profiled once: {"whole": the run in one
    chunk, "chunks": the chunks' runs one after another}. (The profiler slows the calls around the
    kernels most, so these are shares, not the runs' times.)"""
    import cProfile
    import pstats

    runs = _chunk_runs(engine, targets, workers)
    found = {}
    for name, calls in (("whole", [runs.pop("whole")]), ("chunks", list(runs.values()))):
        profile = cProfile.Profile()
        profile.enable()
        for call in calls:
            call()
        profile.disable()
        found[name] = own_time_parts(pstats.Stats(profile))
    return found


def chunked_ratio(one_core, all_cores, whole, parts):
    """The ratio of a :func:`run_trials` call on as many cores as chunks to one on one core had
    its workers cost nothing but their chunks' own time: one core's set-up (from ``one_core``,
    its :func:`timeline_parts`) and ``whole`` (s, the trials in one chunk) over all cores'
    set-up (``all_cores``) and the longest of ``parts`` (s, each chunk's trials alone). Where
    the chunks cost more than the whole, this is the most the pool can reach."""
    return (one_core["set-up"] + whole) / (all_cores["set-up"] + max(parts))


def run_trial_bench(*, trials=512, reference_trials=60, repeats=3, out=print):
    """Grasp trials per second per hand on a ~17k-triangle duck, the engine
    (:mod:`pipeline.trial.engine`, batched) on random MAT candidates, one core; where its time
    goes; its outcomes and, on the first ``reference_trials``, their confusion table against
    :mod:`pipeline.trial.reference` (pybullet's exact queries, the same protocol); and
    :func:`pipeline.trial.protocol.run_trials` of :data:`TRIAL_BATCHES` trials and of a default
    ``simulate`` stage's tables (:data:`STAGE_BATCH`: MAT and baseline) on one core
    (:func:`one_core`), in one process, on every core with the workers of a :class:`TrialPool`
    (started once for the whole bench, as an ablation's calls share theirs) and on every core with
    each call's own workers (as a ``simulate`` stage's one call), in ``repeats`` interleaved rounds
    (:func:`interleaved_seconds`): rates are medians, ratios the median of each round's, and where
    the one-core and all-core calls' time went (:func:`timeline_parts`, medians); and the first
    batch and the stage's tables in one chunk against the chunks run_trials deals them to, each
    alone on one core (:func:`chunks_seconds`, :func:`chunked_ratio`), the same chunks in forked
    copies of this process alone and at once, a core each, run twice (:func:`at_once`,
    :func:`together_factor`: what running together costs on the machine, no pool in between, and
    what a copy's first run costs over its second),
    and where the first batch's own time goes in each (:func:`chunks_own_time`). Returns the rows. (The engine it
    replaced, one pybullet trial at a time, is gone; its rates beside this one's are in
    docs/benchmarks.md.)"""
    with TrialPool() as trial_pool:
        return _trial_bench(trials, reference_trials, repeats, out, trial_pool)


def _trial_bench(trials, reference_trials, repeats, out, trial_pool):
    """:func:`run_trial_bench`, its all-core calls with kept workers in ``trial_pool``."""
    from . import pool
    from .trial.reference import ReferenceEngine

    cores = default_workers(0)
    cpus = sorted(os.sched_getaffinity(0))
    if cores > 1:
        pool.start()  # as the simulate stage does before reading its inputs
    artefacts, faces = trial_bench_chain()
    surface, symmetry = artefacts["sample"], artefacts["classify"]
    settings = SimulateParams()
    batches = (*TRIAL_BATCHES, STAGE_BATCH)
    stage = Params().simulate
    out(f"grasp trials on the duck ({faces} triangles), {trials} random MAT candidates per hand; all cores = {cores}")
    out(
        f"engine: one core, the engine set up. run_trials (the engine's set-up included; {repeats} rounds, "
        "the four ways in turn; rates: medians; ratios: the median of the rounds') of "
        f"{' and '.join(map(str, TRIAL_BATCHES))} trials (distinct candidates of the hand, the engine's first, "
        f"repeated only past all the duck has) and of a {STAGE_BATCH}: the tables of a default simulate stage "
        "on the duck (MAT candidates of 200 spheres and as many baseline ones; a stage has 400-3,300): one core (every "
        "thread of the process held to one CPU), one process (its open3d threads on every core), all "
        "cores with the bench's kept workers (a TrialPool, started before the rounds) and all cores with each "
        "call's own (fresh) workers, as a simulate stage's one call has; ratio: all cores / one core "
        "(/ one process; fresh workers / one core)"
    )
    out(
        f"{'hand':13} {'engine':>7}"
        + "".join(
            f" | {batch:>5}: {'1 core':>7} {'1 proc':>7} {f'{cores} cores':>8} {'fresh':>7} {'ratio':>18}"
            for batch in batches
        )
        + "  engine s in place/retreat/approach/closing/contacts; outcomes"
    )
    out(
        "  then per batch, where run_trials' time went (medians of the rounds): on one core the set-up (the object "
        "mesh and engines) and the trials; on all cores starting the threads that fork the workers, the set-up, the engines' copy for the "
        "workers, the trials in this process and in the busiest worker (its first chunk's start after this "
        "process's), its results' trip back, and the rest of the call after them; the ratio had the workers cost "
        "nothing (these set-ups, one core's trials shared by the cores); then the first batch and the stage's tables "
        "alone on one core in one chunk and in the chunks run_trials deals them to (medians), and the ratio had the "
        "workers cost nothing but those chunks' own time, and those chunks in forked copies of this process (no pool), "
        "each run twice, alone and at once on a core each, and the ratio had the workers cost nothing but the chunks' "
        "own time at once, in copies that had run them before and in fresh ones; "
        "last, the first batch's own time in one chunk and in those "
        "chunks, profiled: in the compiled kernels, in open3d's queries, and in the Python and numpy calls around them"
    )
    rows = []
    for name, hand in HANDS.items():
        # the hand's candidates, generated once (0.6 s on the duck): the engine's sample and the
        # batches below draw from them
        candidates = generate(symmetry, hand)
        table, targets, engine = _warm_engine(surface, candidates, hand, trials, settings)
        engine.seconds = dict.fromkeys(engine.seconds, 0.0)
        with one_core():
            start = time.perf_counter()
            new = [
                result
                for first in range(0, len(table), CHUNK)
                for result in engine.run(*(values[first : first + CHUNK] for values in targets))
            ]
            new_rate = len(table) / (time.perf_counter() - start)
        steps = dict(engine.seconds)
        rates, ratios, parts = {}, {}, {}
        # a batch of distinct candidates, as a simulate stage's: the engine's first, then the
        # object's others (each process's chunk a sample of them; 512 candidates repeated would
        # give each the same 256 four times, their costs never averaging out)
        distinct = drawn_first(candidates, trials)
        runs = {
            batch: [(0, pd.concat([distinct] * (-(-batch // len(distinct))), ignore_index=True).iloc[:batch])]
            for batch in TRIAL_BATCHES
        }
        runs[STAGE_BATCH] = [
            (0, table)
            for _, _, table in trial_tables(
                surface,
                candidates,
                [hand],
                spheres_per_object=stage.spheres_per_object,
                baseline_trials=stage.baseline_trials,
                seed=0,
            )
        ]
        sizes = {batch: sum(len(table) for _, table in tables) for batch, tables in runs.items()}
        # the engine's sample and the stage's tables, each in one chunk and in the chunks
        # run_trials deals it to, alone on one core: what splitting them costs before any worker
        # does; and those chunks in forked copies of this process, alone and together on a core
        # each: what running at once costs on this machine now, pool or not
        samples = {
            TRIAL_BATCHES[0]: targets,
            STAGE_BATCH: candidate_targets(pd.concat([table for _, table in runs[STAGE_BATCH]], ignore_index=True)),
        }
        with one_core():
            split = {
                batch: chunks_seconds(engine, these, repeats, cores, cpus if cores > 1 else None)
                for batch, these in samples.items()
            }
            own_time = chunks_own_time(engine, samples[TRIAL_BATCHES[0]], cores)
        for batch in batches:
            timelines = defaultdict(list)

            def timed(workers, holder, found, shared=None):
                def run():
                    timeline = []
                    with holder():
                        run_trials(
                            surface, [hand], runs[batch], settings, workers=workers, pool=shared, timeline=timeline
                        )
                    found.append(timeline)

                return run

            if batch == batches[0] and cores > 1:  # the kept workers' start and first calls, untimed
                for _ in range(2):
                    timed(cores, contextlib.nullcontext, [], trial_pool)()
            seconds = interleaved_seconds(
                {
                    "core": timed(1, one_core, timelines["core"]),
                    "process": timed(1, contextlib.nullcontext, timelines["process"]),
                    "all": timed(cores, contextlib.nullcontext, timelines["all"], trial_pool),
                    "fresh": timed(cores, contextlib.nullcontext, timelines["fresh"]),
                },
                repeats,
            )
            for key, values in seconds.items():
                rates[batch, key] = sizes[batch] / float(np.median(values))
                found = pd.DataFrame([timeline_parts(timeline) for timeline in timelines[key]])
                parts[batch, key] = {name: round(float(value), 4) for name, value in found.median().items()}
            for key in ("core", "process"):
                ratios[batch, key] = float(np.median(seconds[key] / seconds["all"]))
            ratios[batch, "fresh"] = float(np.median(seconds["core"] / seconds["fresh"]))
        outcomes = Counter(result.outcome for result in new)
        share = "/".join(f"{seconds:.1f}" for seconds in steps.values())
        row = dict(
            hand=name,
            trials=len(table),
            new_per_s=round(new_rate, 1),
            run_trials=[
                dict(
                    batch=batch,
                    trials=sizes[batch],
                    one_core_per_s=round(rates[batch, "core"], 1),
                    one_process_per_s=round(rates[batch, "process"], 1),
                    all_cores_per_s=round(rates[batch, "all"], 1),
                    all_cores_fresh_workers_per_s=round(rates[batch, "fresh"], 1),
                    ratio=round(ratios[batch, "core"], 2),
                    ratio_to_one_process=round(ratios[batch, "process"], 2),
                    ratio_fresh_workers=round(ratios[batch, "fresh"], 2),
                    one_core_s=parts[batch, "core"],
                    all_cores_s=parts[batch, "all"],
                    free_workers_ratio=round(free_workers_ratio(parts[batch, "core"], parts[batch, "all"], cores), 2),
                )
                for batch in batches
            ],
            seconds=steps,
            outcomes=dict(outcomes),
        )
        rows.append(row)
        out(
            f"{name:13} {new_rate:7.1f}"
            + "".join(
                f" | {batch:>5}: {rates[batch, 'core']:7.1f} {rates[batch, 'process']:7.1f} {rates[batch, 'all']:8.1f} "
                f"{rates[batch, 'fresh']:7.1f} {ratios[batch, 'core']:5.2f} ({ratios[batch, 'process']:4.2f}; "
                f"{ratios[batch, 'fresh']:4.2f})"
                for batch in batches
            )
            + f"  {share}; "
            + ", ".join(f"{key} {value}" for key, value in sorted(outcomes.items()))
        )
        for batch in batches:
            one, every = parts[batch, "core"], parts[batch, "all"]
            label = f"{sizes[batch]:>5} trials" + (f" ({batch})" if batch == STAGE_BATCH else "")
            out(
                f"    {label}, s: one core set-up {one['set-up']:.3f} trials {one['caller']:.3f} | "
                f"{cores} cores start {every['start']:.3f} set-up {every['set-up']:.3f} ship {every['ship']:.3f} "
                f"trials {every['caller']:.3f} here, {every['workers']:.3f} in a worker (from {every['lag']:+.3f}), "
                f"its results {every['results']:.3f}, after {every['after']:.3f}; "
                f"ratio with free workers {free_workers_ratio(one, every, cores):.2f}"
            )
        row["chunks"] = []
        for batch, found in split.items():
            whole = float(np.median(found["whole"]))
            pieces = [float(np.median(found[key])) for key in found if key not in ("whole", "forked", "at once")]
            one, every = parts[batch, "core"], parts[batch, "all"]
            ratio = chunked_ratio(one, every, whole, pieces)
            row["chunks"].append(
                dict(
                    batch=batch,
                    trials=len(samples[batch][0]),
                    whole_s=round(whole, 4),
                    chunks_s=[round(value, 4) for value in pieces],
                    ratio_with_chunks=round(ratio, 2),
                )
            )
            label = f"the stage's {sizes[batch]}" if batch == STAGE_BATCH else f"the first {len(samples[batch][0])}"
            out(
                f"    {label} trials alone on one core, s: {whole:.3f} in one chunk, "
                f"{' + '.join(f'{value:.3f}' for value in pieces)} in run_trials' {len(pieces)} "
                f"(+{sum(pieces) / whole - 1:.1%}, the longest {max(pieces) * len(pieces) / whole - 1:+.1%} over an even "
                f"share); ratio with these chunks and the batch's set-ups {ratio:.2f}"
            )
            if "at once" not in found:
                continue
            # (rounds, 2, chunks): each copy's first run, copying the pages it writes, then its second
            forked, together = found["forked"], found["at once"]
            factor = together_factor(forked[:, 1], together[:, 1])
            fresh = together_factor(together[:, 1], together[:, 0])
            reachable = chunked_ratio(one, every, whole, [max(pieces) * factor])
            reachable_fresh = chunked_ratio(one, every, whole, [max(pieces) * factor * fresh])
            medians = {
                (key, name): np.median(found[key][:, run], axis=0)
                for key in ("forked", "at once")
                for run, name in enumerate(("first", "second"))
            }
            row["chunks"][-1].update(
                forked_first_s=[round(float(value), 4) for value in medians["forked", "first"]],
                at_once_first_s=[round(float(value), 4) for value in medians["at once", "first"]],
                forked_s=[round(float(value), 4) for value in medians["forked", "second"]],
                at_once_s=[round(float(value), 4) for value in medians["at once", "second"]],
                at_once_factor=round(factor, 3),
                first_run_factor=round(fresh, 3),
                ratio_with_chunks_at_once=round(reachable, 2),
                ratio_with_first_runs_at_once=round(reachable_fresh, 2),
            )

            def listed(key):
                return " + ".join(f"{value:.3f}" for value in medians[key])

            out(
                f"      the same chunks in forked copies of this process, a core each, s: a copy's second run alone "
                f"{listed(('forked', 'second'))}, at once {listed(('at once', 'second'))} (the longest x{factor:.3f}: "
                f"what running together costs here now); its first alone {listed(('forked', 'first'))}, at once "
                f"{listed(('at once', 'first'))} (the longest x{fresh:.3f} its second's: what a copy's first writes to "
                f"the pages it shares with this process cost here); ratio with the second runs at once and the "
                f"batch's set-ups {reachable:.2f}, with the first runs {reachable_fresh:.2f}"
            )
        row["own_time"] = {
            name: {key: round(value, 4) for key, value in found.items()} for name, found in own_time.items()
        }
        whole, dealt = own_time["whole"], own_time["chunks"]
        out(
            f"    the first {len(targets[0])} trials' own time on one core (cProfile), s: in one chunk "
            + ", ".join(f"{key} {value:.3f}" for key, value in whole.items())
            + "; in run_trials' chunks "
            + ", ".join(f"{key} {value:.3f} ({value - whole[key]:+.3f})" for key, value in dealt.items())
        )
        if not reference_trials:
            continue
        reference = ReferenceEngine(surface, hand, settings)
        start = time.perf_counter()
        checked = reference.run(*(values[:reference_trials] for values in targets))
        reference_rate = len(checked) / (time.perf_counter() - start)
        reference.close()
        against = Counter((result.outcome, other.outcome) for result, other in zip(new, checked))
        agree = sum(n for (a, b), n in against.items() if a == b)
        row.update(
            reference_per_s=round(reference_rate, 2),
            reference_agreement=round(agree / len(checked), 3),
            reference_confusion={f"{a} | {b}": n for (a, b), n in sorted(against.items())},
        )
        out(
            f"    engine | reference (pybullet, {reference_rate:.1f} trials/s): agree {agree}/{len(checked)}; "
            + ", ".join(f"{a} | {b}: {n}" for (a, b), n in sorted(against.items()))
        )
        for number, (result, other) in enumerate(zip(new, checked)):
            if result.outcome != other.outcome:
                out(f"      candidate {number}: " + " | ".join(map(_trial_trace, (result, other))))
    out(
        f"paper: 0.5 s per trial (one core, 2011); target >= 300 trials/s per core and run_trials >= 0.9 x {cores} "
        f"one core's at {cores} cores"
    )
    return rows


def run_check_bench(*, trials=256, physics=100, robust=32, samples=16, out=print):
    """The checks beside plain trials, one core, on the bench's duck: per hand, ``trials`` random
    MAT candidates through the engine (trials/s), pybullet's physics check of up to ``physics``
    of those that closed on the duck (checks/s; and how many held, split by force closure),
    MuJoCo's of the same from the closed pose and from the open hand (checks/s, CPU ms a check,
    held), and robust force closure of the first ``robust`` (``samples`` noisy copies each:
    copies/s). Also the duck's V-HACD time. Returns the rows."""
    from .checks.mujoco_check import MujocoCheck
    from .checks.physics import PhysicsCheck, decompose
    from .trial.engine import CLOSED
    from .checks.robust import robust_force_closure

    artefacts, faces = trial_bench_chain()
    surface, symmetry = artefacts["sample"], artefacts["classify"]
    settings = SimulateParams()
    start = time.perf_counter()
    parts = decompose(surface)
    vhacd = time.perf_counter() - start
    out(
        f"checks on the duck ({faces} triangles; V-HACD {vhacd:.1f} s, {len(parts.part_start) - 1} parts), one core: "
        f"{trials} trials, physics on <= {physics} closed hands, {samples} noisy copies of {robust} trials"
    )
    out(
        f"{'hand':13} {'trials/s':>9} {'checks/s':>9} {'ms/check':>9} {'copies/s':>9}  held: force closure, other closed; "
        "MuJoCo closed / open start: checks/s, CPU ms a check, held"
    )
    rows = []
    for name, hand in HANDS.items():
        _, targets, engine = _warm_engine(surface, generate(symmetry, hand), hand, trials, settings)
        start = time.perf_counter()
        results = engine.run(*targets)
        trial_rate = len(results) / (time.perf_counter() - start)
        closed = [(r, preshape) for r, preshape in zip(results, targets[3]) if r.outcome in CLOSED][:physics]
        check = PhysicsCheck(surface.vertices, surface.faces, hand, engine.model, parts=parts.parts)
        try:
            start = time.perf_counter()
            verdicts = [check.check(r.base_position, r.base_orientation, r.joint_positions) for r, _ in closed]
            check_rate = len(closed) / max(time.perf_counter() - start, 1e-9)
        finally:
            check.close()
        mujoco = MujocoCheck(surface.vertices, surface.faces, hand, engine.model, parts=parts.parts)
        mujoco_rows = {}
        for start in ("closed", "open"):
            begin, cpu = time.perf_counter(), time.process_time()
            count_held = 0
            for r, preshape in closed:
                opened = hand.preshape(preshape)
                keyword = {"open_joints": [opened[j] for j in engine.model.joints]} if start == "open" else {}
                count_held += mujoco.check(r.base_position, r.base_orientation, r.joint_positions, **keyword).success
            seconds, cpu = max(time.perf_counter() - begin, 1e-9), time.process_time() - cpu
            mujoco_rows[start] = (len(closed) / seconds, 1000 * cpu / max(len(closed), 1), count_held)
        seeds = np.random.SeedSequence(0).spawn(robust)
        start = time.perf_counter()
        robust_force_closure(engine, *(values[:robust] for values in targets), seeds, samples=samples)
        copy_rate = robust * samples / (time.perf_counter() - start)
        held = {
            kind: f"{sum(v.success for v, (r, _) in zip(verdicts, closed) if (r.outcome == 'force_closure') == fc)}/"
            f"{sum((r.outcome == 'force_closure') == fc for r, _ in closed)}"
            for kind, fc in (("force_closure", True), ("other", False))
        }
        rows.append(
            dict(
                hand=name,
                trials_per_s=round(trial_rate, 1),
                checks_per_s=round(check_rate, 1),
                ms_per_check=round(1000 / check_rate, 2) if check_rate else None,
                copies_per_s=round(copy_rate, 1),
                held=held,
                vhacd_s=round(vhacd, 2),
                **{
                    f"mujoco_{start}_{key}": round(value, 2)
                    for start, values in mujoco_rows.items()
                    for key, value in zip(("checks_per_s", "cpu_ms_per_check", "held"), values)
                },
            )
        )
        out(
            f"{name:13} {trial_rate:9.1f} {check_rate:9.1f} {rows[-1]['ms_per_check'] or '-':>9} {copy_rate:9.1f}  "
            f"{held['force_closure']}, {held['other']}; "
            + " / ".join(f"{rate:.1f}/s {ms:.1f} ms {count}" for rate, ms, count in mujoco_rows.values())
        )
    out("target: <= 50 ms of CPU per physics check")
    return rows


#: where a stage's time goes: each part the (file suffix, function) pairs of the profiled stage
#: process whose cumulative time it is (imports are counted where they happen too)
STAGE_PARTS = {
    "simulate": (
        ("imports", (("<frozen importlib._bootstrap>", "_find_and_load"),)),
        ("read inputs", (("pipeline/artefacts.py", "load"), ("pipeline/artefacts.py", "read_table"))),
        ("engine set-up", (("pipeline/trial/engine.py", "__init__"),)),
        ("trials", (("pipeline/trial/engine.py", "run"),)),
        ("tables", (("pipeline/trial/protocol.py", "_tables"),)),
        ("write tables", (("pipeline/artefacts.py", "write_table"),)),
        ("log (.mcap)", (("pipeline/logbook.py", "trials"),)),
        ("recording (.rrd)", (("pipeline/outputs/recording.py", "record_stage"),)),
    ),
    "decompose": (
        ("imports", (("<frozen importlib._bootstrap>", "_find_and_load"),)),
        ("read inputs", (("pipeline/artefacts.py", "load"),)),
        ("V-HACD", (("pipeline/checks/physics.py", "decompose"),)),
    ),
    "check": (
        ("imports", (("<frozen importlib._bootstrap>", "_find_and_load"),)),
        ("read inputs", (("pipeline/artefacts.py", "load"), ("pipeline/artefacts.py", "read_table"))),
        ("robust copies' trials", (("pipeline/trial/protocol.py", "run_trials"),)),
        ("pybullet check", (("pipeline/checks/physics.py", "check"),)),
        ("MuJoCo checks", (("pipeline/checks/mujoco_check.py", "check"),)),
        ("write table", (("pipeline/artefacts.py", "write_table"),)),
    ),
}


def _profile_parts(stats, parts):
    """{part: seconds} of a pstats.Stats: each part the cumulative time of its functions (their
    outermost calls, recursion counted once)."""
    found = dict.fromkeys([name for name, _ in parts], 0.0)
    for (filename, _, function), (_, _, _, cumulative, _) in stats.stats.items():
        for name, functions in parts:
            if any(filename.endswith(suffix) and function == wanted for suffix, wanted in functions):
                found[name] += cumulative
    return found


def run_stage_bench(*, data="data", object_name="duck", scale="1.0", hand="barrett", repeats=3, out=print):
    """Where the time of the default run's ``simulate``, ``decompose`` and ``check`` stages goes:
    each stage's command (as ``dvc repro`` runs it, on one core as in a ``make run`` lane) on
    ``data/<object>/<scale>`` (the DAG's artefacts: run ``dvc repro`` or ``dvc pull`` first),
    its outputs in a temporary folder, profiled. Prints per stage the process's wall time and
    its parts: interpreter start, imports (wherever they happen), reading inputs, the work,
    writing; then, with several cores, the ``simulate`` command unprofiled on one core and on
    every core (its trial workers), ``repeats`` rounds in turn: medians and the median of the
    rounds' ratios. Returns the rows."""
    import os
    import pstats
    import sys
    import tempfile
    from pathlib import Path

    from .errors import BadInputError

    run = Path(data) / object_name / scale
    needed = [run / "surface.npz", run / hand / "candidates.parquet", run / hand / "trials.parquet"]
    for path in needed:
        if not path.is_file():
            raise BadInputError(f"{path}: missing; the stage bench reads the DAG's artefacts (dvc repro or dvc pull)")
    rows = []
    out(f"stages on {run} ({hand}), one core each, profiled (cProfile adds to Python-heavy parts)")
    out(f"{'stage':10} {'wall s':>7} {'start s':>7} {'imports':>7}  parts (s)")
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        commands = {
            "simulate": [run / "surface.npz", run / hand / "candidates.parquet", hand]
            + [folder / "trials.parquet", folder / "contacts.parquet", "--rrd", folder / "grasps.rrd"]
            + ["--recording-id", f"{object_name}-{scale}"],
            "decompose": [run / "surface.npz", scale, folder / "parts.npz"],
            "check": [
                run / "surface.npz",
                folder / "trials.parquet",
                folder / "parts.npz",
                scale,
                hand,
                folder / "checks.parquet",
            ],
        }
        for stage, arguments in commands.items():
            profile = folder / f"{stage}.prof"
            command = [sys.executable, "-m", "cProfile", "-o", str(profile), "-m", f"stages.{stage}"]
            command += [str(value) for value in arguments] + ["--log", str(folder / f"{stage}.mcap")]
            start = time.perf_counter()
            _stage_command(command, {min(os.sched_getaffinity(0))})  # one core, as a make run lane
            wall = time.perf_counter() - start
            stats = pstats.Stats(str(profile))
            parts = _profile_parts(stats, STAGE_PARTS[stage])
            imports = parts.pop("imports")
            parts["other"] = stats.total_tt - sum(parts.values())
            started = wall - stats.total_tt
            rows.append(
                dict(
                    stage=stage,
                    wall_s=round(wall, 2),
                    start_s=round(started, 2),
                    imports_s=round(imports, 2),
                    **{k: round(v, 2) for k, v in parts.items()},
                )
            )
            out(
                f"{stage:10} {wall:7.1f} {started:7.1f} {imports:7.1f}  "
                + ", ".join(f"{name} {seconds:.1f}" for name, seconds in parts.items())
            )
        cores = default_workers(0)
        if cores > 1:
            command = [sys.executable, "-m", "stages.simulate", *map(str, commands["simulate"])]
            seconds = interleaved_seconds(
                {
                    "core": lambda: _stage_command(command, {min(os.sched_getaffinity(0))}),
                    "all": lambda: _stage_command(command),
                },
                repeats,
            )
            one_core, all_cores = (float(np.median(seconds[key])) for key in ("core", "all"))
            ratio = float(np.median(seconds["core"] / seconds["all"]))
            rows.append(
                dict(
                    stage="simulate",
                    cores=cores,
                    one_core_s=round(one_core, 2),
                    all_cores_s=round(all_cores, 2),
                    ratio=round(ratio, 2),
                )
            )
            out(
                f"simulate unprofiled ({repeats} rounds, in turn): 1 core {one_core:.2f} s, {cores} cores "
                f"{all_cores:.2f} s, ratio {ratio:.2f}"
            )
    out(
        "start: interpreter start and exit, outside the profile; imports: wherever they happen, so also inside "
        "the parts they happen in (other: the rest, top-level imports included)"
    )
    return rows


def _stage_command(command, cpus=None):
    """Run a stage's ``command`` (from the repository root), held to ``cpus`` when given; raises
    with its output when it fails. Its output goes to a file: the trial workers' fork server
    holds the command's streams until it ends, after the command."""
    import subprocess
    import tempfile

    from .dag import ROOT

    with tempfile.TemporaryFile("w+") as output:
        process = subprocess.Popen(command, cwd=ROOT, stdout=output, stderr=subprocess.STDOUT, text=True)
        if cpus:
            os.sched_setaffinity(process.pid, cpus)
        if process.wait():
            output.seek(0)
            raise RuntimeError(f"{' '.join(command)} failed:\n{output.read()}")


def occupancy(spans):
    """{stages running: seconds} over the time from the first of ``spans`` ((start, end) pairs,
    s) to the last end."""
    events = sorted([(start, 1) for start, _ in spans] + [(end, -1) for _, end in spans])
    found, level, last = Counter(), 0, events[0][0] if events else 0.0
    for moment, change in events:
        found[level] += moment - last
        level, last = level + change, moment
    return {running: seconds for running, seconds in sorted(found.items()) if seconds > 0}


def lane_gaps(spans):
    """The waits between one stage and the next of the same lane, from the stages' ``spans``
    ((start, end, name) each, s; a name ``object/stage``): each stage goes to a lane that was
    free when it started (a new lane if none was), the one whose last stage was of the same
    object if any (a lane runs an object's stages in a row), else the one that freed last.
    Returns (seconds, name before, name after) per wait, in start order."""
    lanes, gaps = [], []  # each lane: [end, name] of its last stage

    def rank(lane, name):
        return lane[1].partition("/")[0] == name.partition("/")[0], lane[0]

    for start, end, name in sorted(spans):
        free = [lane for lane in lanes if lane[0] <= start]
        if free:
            lane = max(free, key=lambda lane: rank(lane, name))
            gaps.append((start - lane[0], lane[1], name))
            lane[:] = [end, name]
        else:
            lanes.append([end, name])
    return gaps


def run_occupancy_bench(*, logs="logs", out=print):
    """How the last ``dvc repro`` (``make run``) kept the cores busy, from the stage logs under
    ``logs``: each stage from its ``/stage`` start message to its end (its process start and
    imports before them count as not running). Prints the stages, the time from the first start
    to the last end, the stages' own seconds, and the seconds with 0, 1, 2, ... stages running:
    fewer than the lanes is DVC's work between stages, process starts, the kernels' compilation
    and a lane waiting at the end. Then the waits between one stage and the next of a lane
    (:func:`lane_gaps`): DVC's own work after a stage and before the next, and the next one's
    process start and imports. Returns the row."""
    from pathlib import Path

    from mcap.reader import make_reader

    from .errors import BadInputError

    spans = []
    for path in sorted(Path(logs).rglob("*.mcap")):
        with open(path, "rb") as stream:
            times = [message.log_time / 1e9 for _, _, message in make_reader(stream).iter_messages(topics=["/stage"])]
        if len(times) == 2:
            folder = path.relative_to(logs).parts[:-1]
            spans.append((min(times), max(times), f"{folder[0]}/{path.stem}" if folder else path.stem))
    if not spans:
        raise BadInputError(f"{logs}: no stage logs; `make run` (or dvc repro) writes them")
    levels = occupancy([(start, end) for start, end, _ in spans])
    first, last = min(start for start, _, _ in spans), max(end for _, end, _ in spans)
    gaps = lane_gaps(spans)
    waits = np.array([seconds for seconds, _, _ in gaps])
    row = dict(
        stages=len(spans),
        span_s=last - first,
        stage_s=sum(end - start for start, end, _ in spans),
        running_s=levels,
        waits=dict(
            count=len(gaps),
            seconds=float(waits.sum()),
            median_s=float(np.median(waits)) if len(gaps) else float("nan"),
            p90_s=float(np.percentile(waits, 90)) if len(gaps) else float("nan"),
        ),
    )
    out(
        f"the stage logs under {logs}: {row['stages']} stages over {row['span_s']:.0f} s, {row['stage_s']:.0f} s of stage work"
    )
    out("stages running  seconds")
    for running, seconds in levels.items():
        out(f"{running:14d}  {seconds:7.0f}")
    if gaps:
        waited = row["waits"]
        out(
            f"between two stages of a lane (DVC's work after one and before the next, its process start and "
            f"imports; the lanes told apart by the objects): {waited['count']} waits, {waited['seconds']:.0f} s in all, "
            f"median {waited['median_s']:.2f} s, 90 % within {waited['p90_s']:.2f} s"
        )
    return row


def run_evaluate_bench(*, grasps=64, out=print):
    """``evaluate``'s labelling beside plain trials, one core, on the bench's duck: per hand,
    the closed poses and open joints of the first ``grasps`` MAT trials that closed (what an
    export of them holds) labelled by :class:`pipeline.outputs.evaluate.Labeller` at the default params
    (closed in place, ``checks.robust_samples`` noisy copies, the lift-and-shakes of
    ``checks.engine`` on those that closed): grasps/s with every verdict and with the close in
    place alone, beside the trials/s of the same candidates. Returns the rows."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from .checks.physics import decompose
    from .outputs.evaluate import Labeller, verdict_settings
    from .trial.engine import CLOSED

    artefacts, faces = trial_bench_chain()
    surface, symmetry = artefacts["sample"], artefacts["classify"]
    params = Params()
    settings, physics, robust = verdict_settings(SimpleNamespace(friction=None, mass_kg=None), params)
    parts = decompose(surface).parts
    out(
        f"evaluate on the duck ({faces} triangles), one core: {grasps} closed MAT grasps per hand, "
        f"{robust['samples']} noisy copies each, the lift-and-shakes ({', '.join(physics)}) on those that close"
    )
    out(f"{'hand':13} {'trials/s':>9} {'in place/s':>11} {'evaluate/s':>11} {'ms/grasp':>9}  outcomes")
    rows = []
    for name, hand in HANDS.items():
        _, targets, engine = _warm_engine(surface, generate(symmetry, hand), hand, 4 * grasps, settings)
        start = time.perf_counter()
        results = engine.run(*targets)
        trial_rate = len(results) / (time.perf_counter() - start)
        closed = [(result, preshape) for result, preshape in zip(results, targets[3]) if result.outcome in CLOSED]
        closed = closed[:grasps]
        base = np.tile(np.eye(4), (len(closed), 1, 1))
        base[:, :3, :3] = Rotation.from_quat([result.base_orientation for result, _ in closed]).as_matrix()
        base[:, :3, 3] = [result.base_position for result, _ in closed]
        joints = engine.model.joints
        open_joints = np.array([[hand.preshape(preshape)[joint] for joint in joints] for _, preshape in closed])
        labeller = Labeller(
            surface.vertices, surface.faces, hand, parts, settings=settings, physics=physics, robust=robust, seed=0
        )
        try:
            labeller.engine.close_in_place(base[:2], open_joints[:2])  # numba's first calls: start-up
            start = time.perf_counter()
            labeller.engine.close_in_place(base, open_joints)
            in_place_rate = len(closed) / (time.perf_counter() - start)
            start = time.perf_counter()
            table = labeller.label(np.arange(len(closed)), base, open_joints)
            evaluate_rate = len(closed) / (time.perf_counter() - start)
        finally:
            labeller.close()
        outcomes = dict(Counter(table.outcome))
        rows.append(
            dict(
                hand=name,
                grasps=len(closed),
                trials_per_s=round(trial_rate, 1),
                in_place_per_s=round(in_place_rate, 1),
                evaluate_per_s=round(evaluate_rate, 2),
                ms_per_grasp=round(1000 / evaluate_rate, 1),
                outcomes=outcomes,
            )
        )
        out(
            f"{name:13} {trial_rate:9.1f} {in_place_rate:11.1f} {evaluate_rate:11.2f} {1000 / evaluate_rate:9.1f}  "
            + ", ".join(f"{key} {value}" for key, value in sorted(outcomes.items()))
        )
    return rows


def run_recording_bench(*, trials=500, repeats=3, out=print):
    """What the stages' recordings add to one object's run, on the duck, one core: the geometry
    chain (sample ... classify) against classify's ``object.rrd``; per hand, ``trials`` MAT
    trials against the ``grasps.rrd`` of simulate (its candidates and trials) and the MCAP
    ``/trials``; and ``import rerun`` in a fresh process, paid once by each recording stage.
    500 trials per hand is a default run's simulate stage (50 spheres, as many baseline trials).
    Recording times are medians of ``repeats``. Returns the rows."""
    import subprocess
    import sys
    import tempfile
    from pathlib import Path

    from .logbook import mcap_log
    from .outputs.recording import log_candidates, log_spheres, log_surface, log_symmetry, rerun_recording
    from .outputs.trial_recording import log_trials
    from .trial.protocol import simulate

    def median_seconds(action, count):
        times = []
        for _ in range(count):
            start = time.perf_counter()
            action()
            times.append(time.perf_counter() - start)
        return float(np.median(times))

    start = time.perf_counter()
    artefacts, faces = trial_bench_chain()
    surface, grid, symmetry = artefacts["sample"], artefacts["sphere_grid"], artefacts["classify"]
    geometry = time.perf_counter() - start
    bare = median_seconds(lambda: subprocess.run([sys.executable, "-c", "pass"], check=True), repeats)
    imported = median_seconds(lambda: subprocess.run([sys.executable, "-c", "import rerun"], check=True), repeats)
    importing = max(imported - bare, 0.0)
    out(
        f"recording cost on the duck ({faces} triangles, {len(grid)} medial spheres): {trials} MAT trials per hand, "
        f"one core; recording = median of {repeats}"
    )
    out(f"{'what':34} {'work s':>8} {'record s':>9} {'ratio':>7}")
    rows = []

    def row(name, work, recorded):
        rows.append(
            dict(
                what=name,
                work_s=round(work, 3),
                record_s=round(recorded, 3),
                ratio=round(recorded / work, 3) if work else None,
            )
        )
        out(f"{name:34} {work:8.2f} {recorded:9.3f} " + (f"{100 * recorded / work:6.1f}%" if work else ""))

    with tempfile.TemporaryDirectory() as folder:
        rrd, log_path = Path(folder) / "bench.rrd", Path(folder) / "bench.mcap"

        def record_object():
            with rerun_recording(rrd, recording_id="bench") as stream:
                log_surface(stream, "/duck", surface)
                log_spheres(stream, "/duck", grid)
                log_symmetry(stream, "/duck", symmetry)

        row("import rerun (each recording stage)", 0.0, importing)
        row("sample..classify: object.rrd", geometry, median_seconds(record_object, repeats))
        work, recorded = geometry, importing + rows[-1]["record_s"]
        for name, hand in HANDS.items():
            candidates = generate(symmetry, hand)
            table = candidates.sample(min(trials, len(candidates)), random_state=0).reset_index(drop=True)
            start = time.perf_counter()
            results, contacts = simulate(
                surface, table, [hand], spheres_per_object=len(table), baseline_trials=0, workers=1
            )
            simulated = time.perf_counter() - start

            def record_grasps():
                with rerun_recording(rrd, recording_id="bench") as stream:
                    log_candidates(stream, "/duck", candidates)
                    log_trials(stream, "/duck", surface, hand, results, contacts)
                with mcap_log(log_path, "simulate") as log:
                    log.trials(results)

            row(f"simulate {name}: grasps.rrd + MCAP", simulated, median_seconds(record_grasps, repeats))
            work, recorded = work + simulated, recorded + importing + rows[-1]["record_s"]
        row("the object, every hand", work, recorded)
    out(
        "target: recording adds <= 20 % to a run. Not counted here: the stage processes' own start-up, "
        "which `dvc repro` also pays (the report's time table gives the whole run's figure)"
    )
    return rows


def run_batch_bench(*, objects=20, hands=("armar3", "barrett", "parallel_jaw"), spheres=10, out=print):
    """Objects per minute of ``python -m pipeline batch`` on the first ``objects`` of pybullet's
    random_urdfs with 1 and 2 workers of an embedded Ray (default params, ``spheres`` per object
    and hand), the scaling efficiency, and a projection of 1000 objects x 3 hands on 16 and
    4 x 16 cores from the measured cost per object. Returns the rows."""
    import dataclasses
    import tempfile

    from .batch import find_meshes, run_batch

    params = Params()
    params = dataclasses.replace(params, simulate=dataclasses.replace(params.simulate, spheres_per_object=spheres))
    meshes = find_meshes("pybullet:random_urdfs")[:objects]
    out(
        f"batch on {len(meshes)} random_urdfs objects x {len(hands)} hands, {spheres} spheres per object and hand "
        f"(default params otherwise), embedded Ray, one run each"
    )
    out(f"{'workers':>7} {'ray start s':>11} {'work s':>7} {'objects/min':>11} {'efficiency':>10}")
    rows = []
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as folder:
            counts = run_batch(meshes, folder, hands=list(hands), params=params, scale=0.015, workers=workers)
        work = counts["seconds"] - counts["ray_start_s"]
        rate = 60 * len(meshes) / work
        efficiency = rate / (workers * rows[0]["objects_per_min"]) if rows else 1.0
        rows.append(
            dict(
                workers=workers,
                ray_start_s=round(counts["ray_start_s"], 2),
                work_s=round(work, 2),
                objects_per_min=round(rate, 2),
                efficiency=round(efficiency, 3),
                ok=counts["ok"],
                error=counts["error"],
                failed=counts["failed"],
            )
        )
        out(f"{workers:7d} {counts['ray_start_s']:11.1f} {work:7.1f} {rate:11.1f} {efficiency:10.2f}")
    core_seconds = rows[0]["work_s"] / len(meshes)
    efficiency = min(rows[-1]["efficiency"], 1.0)  # above 1 is noise; do not project a speed-up
    for cores, name in ((16, "16 cores"), (64, "4 x 16 cores")):
        minutes = 1000 * core_seconds / (cores * efficiency) / 60
        out(
            f"projection: 1000 objects x {len(hands)} hands on {name}: {minutes:.1f} min + Ray start "
            f"({core_seconds:.2f} core-s per object, efficiency {efficiency:.2f})"
        )
    return rows

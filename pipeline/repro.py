"""``dvc repro`` of the whole DAG with the objects' chains in parallel lanes (``make run``).

DVC runs one stage at a time, and every stage before ``simulate`` uses one core, as does DVC's
own work between stages: on two cores half the machine would wait through most of the run. But
DVC releases its repository lock while a stage's command runs and guards each stage's deps and
outs with read/write locks, so several ``dvc repro`` processes may run stages whose files do not
overlap, and the objects do not share files until the report. So:

1. ``python -m pipeline.dag``: the stage files of params.yaml's objects;
2. ``dvc repro -s`` of the ``code`` stages (the fingerprints every lane reads);
3. ``jobs`` lanes, each taking the next object and running ``dvc --wait-for-lock repro -s`` of
   its stage files in DAG order up to the last stage before the trial engine's first
   (:func:`phases`: ``candidates``; a stage that is up to date is skipped, as in ``dvc repro``),
   while one more process compiles the trial engine's numba kernels into their cache
   (:func:`compile_kernels`): every trial process would otherwise compile them itself until one
   has written the cache (38 s of one core for the two default hands);
4. the same lanes over the objects' other stages in two rounds (:func:`rounds`): ``simulate`` and
   ``decompose``, then ``check``; a lane takes an object's checks once its first round is done,
   the costliest first (:func:`check_work`, estimated from the object's trials), so that the
   run does not end on one lane checking a heavy object while the other waits;
5. ``dvc repro``: the report, and DVC's own check that nothing else is left to run.

From step 3 on, the stage commands run in processes forked from a warm stage server
(:mod:`pipeline.stage_server`, started beside steps 1-2) instead of each importing the libraries
anew.

Every run is the one ``dvc repro`` would make (the stages are deterministic and do not depend
on what runs beside them), so the artefacts and dvc.lock files are the same; only the order
differs. The lanes' output is printed line by line, each line after its object's name; the
first lane that fails stops the others from starting new tasks, and the command fails with
its object's output.
"""

import collections
import contextlib
import os
import shutil
import subprocess
import sys
import tempfile
import threading

from . import dag
from .dag import ROOT, STAGES, object_stage_file, stage_file
from .stage_server import ADDRESS

DVC = [sys.executable, "-m", "dvc"]


def lane_targets(object_name, stages=STAGES):
    """Repository-relative stage files of one object for ``stages``, in DAG order."""
    return [object_stage_file(entry.name, object_name) for entry in stages]


def phases(stages=STAGES):
    """(the stages before the first whose code runs the trial engine, the rest): the lanes run
    the first part while the engine's kernels compile, the rest after."""
    engine = "pipeline/trial/engine.py"
    for number, entry in enumerate(stages):
        if engine in dag.code_deps(entry.name):
            return stages[:number], stages[number:]
    return stages, ()


def compile_kernels(hands):
    """One trial of each hand (names) on a 4 cm cube, so that numba compiles the engine's kernels
    into its cache (or finds them there)."""
    import dataclasses

    import numpy as np

    from .errors import PipelineError
    from .geometry.sampling import sample_object
    from .hands.spec import get_hand
    from .params import SampleParams
    from .trial.engine import GraspEngine

    cube = sample_object(
        "primitive:box",
        shape={"extents": (0.04, 0.04, 0.04)},
        rng=np.random.default_rng(0),
        **{**dataclasses.asdict(SampleParams()), "count": 2000},
    )
    for name in hands:
        try:
            hand = get_hand(name)
        except PipelineError:  # its candidates stage says so, in one line
            continue
        GraspEngine(cube, hand).run(
            np.array([[0.0, 0.0, 0.02]]), np.array([[0.0, 0.0, -1.0]]), np.array([[1.0, 0.0, 0.0]]), [None]
        )


def _run(command, prefix, lock, cores=None):
    """Run ``command`` in the repository (on the CPU set ``cores``, if given), printing its
    output lines after ``prefix``; the exit status and the output's last lines."""
    process = subprocess.Popen(
        command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, errors="replace"
    )
    if cores:  # before DVC starts a stage: the stages inherit it
        os.sched_setaffinity(process.pid, cores)
    tail = collections.deque(maxlen=40)
    for line in process.stdout:
        tail.append(line.rstrip())
        with lock:
            print(f"{prefix}{tail[-1]}", flush=True)
    return process.wait(), list(tail)


def lane_cores(lanes):
    """The CPU set of each of ``lanes`` lanes (a share of this process's each, or None for all
    of them when there are more lanes than cores)."""
    available = sorted(os.sched_getaffinity(0))
    return [set(available[lane::lanes]) if lanes <= len(available) else None for lane in range(lanes)]


@contextlib.contextmanager
def warm_server(cpus=None):
    """A :mod:`pipeline.stage_server` on the CPU set ``cpus``, started now; the context gives a
    function that waits until it serves and returns its socket path (None if it failed to
    start: the stages then run in their own processes). Stopped on exit."""
    folder = tempfile.mkdtemp(prefix="medial-grasp-")
    address = os.path.join(folder, "stages.sock")
    command = [sys.executable, "-m", "pipeline.stage_server", address]
    if cpus:
        command += ["--cpus", ",".join(map(str, sorted(cpus)))]
    server = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, text=True)

    def ready():
        return address if server.stdout.readline().strip() == "ready" else None

    try:
        yield ready
    finally:
        server.kill()
        server.wait()
        server.stdout.close()
        shutil.rmtree(folder, ignore_errors=True)


#: seconds of physics checks a closed hand's trial costs (pybullet's and MuJoCo's two; the
#: default objects' median), in :func:`check_work`'s estimate
PHYSICS_CHECK_S = 0.2


def check_work(object_name, params, data=None):
    """An estimate (s of one core) of the ``check`` stages of one object, from the trials its
    ``simulate`` stages wrote: per run, its checked trials (``checks.trials`` per planner) times
    ``checks.robust_samples`` noisy copies at the run's own seconds per trial, plus
    :data:`PHYSICS_CHECK_S` per checked trial whose hand closed. Only an order: within 10-40 %
    of the default run's check stages. 0 for a run whose files are missing."""
    import json

    import pandas as pd

    from .trial.engine import CLOSED

    data = ROOT / "data" if data is None else data
    checks, total = params.checks, 0.0
    for scale in params.scales:
        for hand in params.candidates.hands:
            run = data / object_name / str(float(scale)) / hand
            try:
                trials = pd.read_parquet(run / "trials.parquet", columns=["planner", "outcome"])
                seconds = json.loads((run / "timing" / "simulate.json").read_text())["process_seconds"]
            except (OSError, ValueError, KeyError):
                continue
            per_trial = seconds / max(len(trials), 1)
            for _, planner in trials.groupby("planner", observed=True):
                checked = len(planner) if checks.trials < 0 else min(checks.trials, len(planner))
                closed = checked * float(planner.outcome.astype(str).isin(CLOSED).mean())
                total += checked * checks.robust_samples * per_trial + (
                    closed * PHYSICS_CHECK_S if checks.physics else 0
                )
    return total


def rounds(stages=STAGES):
    """The lanes' rounds of stages: :func:`phases`' first part (run while the kernels compile),
    then its second but for the last stage, then the last (``check``) alone, each round a task
    per object. Two smaller tasks instead of one at the end leave one lane idle for less of the
    time the other finishes its last object (about 40 s of a default run's 20 minutes)."""
    before, after = phases(stages)
    return tuple(part for part in (before, after[:-1], after[-1:]) if part)


def run_lanes(objects, jobs, rounds=(STAGES,), cost=None):
    """Reproduce every object's stages, round by round (sequences of :class:`Stage`), ``jobs``
    tasks at a time; the names of the objects that failed, with their output's last lines (empty
    when all succeeded).

    A task is one object's stages of one round; a lane takes the first in round order whose
    object has no task running (so its earlier rounds are done); in the last of several
    rounds, of those the one of the highest ``cost(object)`` (estimated once, when first
    ready). With no more lanes than cores each lane keeps to its share of them (one each when
    there are as many lanes): ``simulate`` (``workers: 0``, every core the process may use)
    then runs its trials on that share, in its own process when it is one core, instead of
    starting worker processes that would compete with the lanes beside it."""
    queue = [(number, name, stages) for number, stages in enumerate(rounds) if stages for name in objects]
    last, estimates = len(rounds) - 1 if cost and len(rounds) > 1 else None, {}

    def pick(ready):  # the first task of the earliest round; in the last, the costliest
        first = min(number for number, _, _ in ready)
        earliest = [task for task in ready if task[0] == first]
        if first != last:
            return earliest[0]
        for _, name, _ in earliest:  # its object's earlier rounds are done: their files are there
            if name not in estimates:
                estimates[name] = cost(name)
        return max(earliest, key=lambda task: estimates[task[1]])  # the first of equals

    running, failed, output, changed = set(), {}, threading.Lock(), threading.Condition()
    width = max(map(len, objects), default=0)
    lanes = max(1, min(jobs, len(objects)))
    cores = lane_cores(lanes)

    def lane(number):
        while True:
            with changed:
                while not failed and queue and not (ready := [task for task in queue if task[1] not in running]):
                    changed.wait()
                if failed or not queue:
                    return
                task = pick(ready)
                _, name, stages = task
                queue.remove(task)
                running.add(name)
            command = DVC + ["--wait-for-lock", "repro", "-s"] + lane_targets(name, stages)
            status, tail = _run(command, f"[{name:<{width}}] ", output, cores[number])
            with changed:
                running.discard(name)
                if status:
                    failed[name] = tail
                changed.notify_all()

    threads = [threading.Thread(target=lane, args=(number,)) for number in range(lanes)]
    for thread in threads:
        thread.start()
    try:
        for thread in threads:
            thread.join()
    except KeyboardInterrupt:  # the lanes' dvc got it too: let them stop, start no more
        with changed:
            queue.clear()
            changed.notify_all()
        raise
    return failed


def main(argv=None):
    import argparse

    from .errors import PipelineError
    from .params import load_params
    from .pool import default_workers

    parser = argparse.ArgumentParser(prog="python -m pipeline.repro", description=__doc__.split("\n\n")[0])
    parser.add_argument("--jobs", type=int, default=0, help="lanes (objects at once); 0 = every core")
    args = parser.parse_args(argv)
    try:
        params = load_params(ROOT / "params.yaml")
        dag.main([])  # the stage files of its objects
    except PipelineError as error:
        raise SystemExit(f"error: {error}") from None
    objects, jobs, lock = list(params.objects), default_workers(args.jobs), threading.Lock()
    with warm_server(lane_cores(max(1, min(jobs, len(objects))))[0]) as server_ready:
        if _run(DVC + ["repro", "-s"] + [stage_file(entry.name) for entry in STAGES], "", lock)[0]:
            raise SystemExit(1)
        address = server_ready()
        if address:  # the stage commands DVC starts from here on find it
            os.environ[ADDRESS] = address
        else:
            print("the stage server did not start (see above): every stage runs in its own process", flush=True)
        kernels = subprocess.Popen(
            [
                sys.executable,
                "-c",
                f"from pipeline.repro import compile_kernels; compile_kernels({list(params.candidates.hands)!r})",
            ],
            cwd=ROOT,
        )
        first, *later = rounds()
        failed = run_lanes(objects, jobs, (first,))
        if kernels.wait():
            raise SystemExit("error: compiling the trial engine's kernels failed (see above)")
        failed = failed or run_lanes(objects, jobs, later, cost=lambda name: check_work(name, params))
        if failed:
            for name, tail in failed.items():
                print(f"\n{name} failed; its last lines:\n" + "\n".join(tail), file=sys.stderr)
            raise SystemExit(
                f"error: the stages of {', '.join(failed)} failed (see above); `dvc repro` reruns what is left"
            )
        status = _run(DVC + ["repro"], "", lock)[0]
    raise SystemExit(status)


if __name__ == "__main__":
    try:
        main()
    except KeyboardInterrupt:
        raise SystemExit("interrupted; `make run` again reruns only what is left") from None

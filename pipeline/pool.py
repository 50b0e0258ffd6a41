"""The trial worker processes' start: a fork server that imports the trial engine once.

Spawned workers would each import numpy, open3d and numba and load the engine's numba kernels
before their first trial (about 3 s a process here, every ``simulate`` stage). Workers forked
from a server that has only imported them (:mod:`pipeline.kernel_cache`) start at once; the
server itself is a fresh single-threaded process that has run nothing, so no thread of a used
library (open3d's ray casting, OpenMP) is copied mid-flight, as forking the caller could.
:func:`start` launches it early, so that its imports overlap the caller's.
"""

import multiprocessing
import os

#: what the server imports before forking workers (the engine's lazy imports included; its numba
#: kernels loaded from their cache; the modules of the engines' settings and hands, which a worker
#: would otherwise import while it unpickles them, 0.02 s). Not trimesh: the caller's set-up meshes
#: the hands' and the object's shapes, and a worker, which loads the engines and runs trials, never
#: imports it; its 0.4 s here came before a stage's first worker
PRELOAD = [
    "pipeline.trial.engine",
    "pipeline.params",
    "pipeline.hands.spec",
    "open3d",
    "pipeline.kernel_cache",
]

#: the server's environment beside the caller's, which its workers inherit: OpenBLAS on the
#: calling thread alone. A process forked from one whose OpenBLAS has helper threads starts them
#: anew at its first call that sets or uses them (threadpoolctl's, in a trial's grading:
#: :mod:`pipeline.threads`), and each spins about 0.1 s before it sleeps, on the cores the trial
#: processes fill: 0.2 s of a core per worker, at its first chunk (a fresh worker's 256 trials of
#: Barrett on the duck took 0.52 s there, 0.42-0.44 s after). The workers, one per core, never
#: split a product between threads: their trials' results are the same
SERVER_ENVIRONMENT = {"OPENBLAS_NUM_THREADS": "1"}


def default_workers(workers):
    """``workers`` processes, or every core the process may use when 0."""
    return workers if workers > 0 else len(os.sched_getaffinity(0))


def context():
    """The ``multiprocessing`` context of the trial workers, their fork server running (:func:`start`)."""
    start()
    return multiprocessing.get_context("forkserver")


def start():
    """Start the fork server now, if it is not running: it imports :data:`PRELOAD` while the
    caller goes on, in the caller's environment and :data:`SERVER_ENVIRONMENT`."""
    from multiprocessing import forkserver

    multiprocessing.get_context("forkserver").set_forkserver_preload(PRELOAD)
    saved = {name: os.environ.get(name) for name in SERVER_ENVIRONMENT}
    os.environ.update(SERVER_ENVIRONMENT)
    try:
        forkserver.ensure_running()
    finally:
        for name, value in saved.items():
            if value is None:
                del os.environ[name]
            else:
                os.environ[name] = value

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


def default_workers(workers):
    """``workers`` processes, or every core the process may use when 0."""
    return workers if workers > 0 else len(os.sched_getaffinity(0))


def context():
    """The ``multiprocessing`` context of the trial workers."""
    ctx = multiprocessing.get_context("forkserver")
    ctx.set_forkserver_preload(PRELOAD)
    return ctx


def start():
    """Start the fork server now (it imports :data:`PRELOAD` while the caller goes on)."""
    from multiprocessing import forkserver

    context()
    forkserver.ensure_running()

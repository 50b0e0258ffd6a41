"""What the tests have a trial pool's worker run, in a module of its own: a worker imports the
module of each function it runs, and the test modules import trimesh, which a worker must not
need (tests/test_simulation.py)."""

import sys


def trials_and_trimesh(copy, hand_number, grasp, approach, orient, preshapes):
    """The outcomes of :func:`pipeline.trial.engine.run_chunk`'s trials, and whether this
    process has imported trimesh by then."""
    from pipeline.trial.engine import run_chunk

    results, _, _ = run_chunk(copy, hand_number, grasp, approach, orient, preshapes)
    return [result.outcome for result in results], "trimesh" in sys.modules


def blas_threads_and_threads_gained():
    """threadpoolctl's thread counts of the BLAS libraries in this process, and the threads it
    gained from a product on one BLAS thread, as a trial's grading runs one."""
    import os

    import numpy as np
    from threadpoolctl import threadpool_info

    from pipeline.threads import one_blas_thread

    before = len(os.listdir("/proc/self/task"))
    with one_blas_thread():
        np.ones((64, 6)) @ np.ones((6, 8))
    gained = len(os.listdir("/proc/self/task")) - before
    return [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"], gained

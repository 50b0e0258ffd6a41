"""The trial processes' BLAS threads: one, on the thread that calls it.

numpy and scipy ship OpenBLAS, which starts a helper thread per CPU at load and splits a large
enough product between them (grading a grasp multiplies thousands of wrenches by a hull's facet
normals). Its helpers then spin, waiting for the next one, on the CPUs the trial processes
already fill: one process per core (:func:`pipeline.trial.protocol.run_trials`), and on a
one-core machine the caller's own. On the duck, one core, Barrett's default simulate stage in
run_trials' two chunks: grading the second took 0.467 s with OpenBLAS's two threads, 0.281 s with
one, the first 0.281 and 0.271 s (medians of 7 rounds); every trial's result the same bytes.
"""

import functools


@functools.cache
def _controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()  # the BLAS libraries loaded by now (numpy's, scipy's): 6-21 ms, once


def one_blas_thread():
    """A context manager inside which the loaded BLAS libraries run on the calling thread alone."""
    return _controller().limit(limits=1, user_api="blas")


def on_one_blas_thread(function):
    """``function`` run inside :func:`one_blas_thread` (a decorator)."""

    @functools.wraps(function)
    def wrapped(*args, **kwargs):
        with one_blas_thread():
            return function(*args, **kwargs)

    return wrapped

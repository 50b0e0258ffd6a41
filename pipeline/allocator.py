"""How the trial processes manage memory: the C allocator's limits, set for array code that frees
and allocates the same memory over and over (the trial engine's closing passes), and the garbage
collector's full passes, kept off the objects that outlive a batch of trials.

glibc's malloc hands an allocation at or above its mmap threshold fresh pages from the system and
unmaps them when freed, and trims the heap's free top once it passes the trim threshold. Both
start low (128 KB; the mmap threshold then rises to the largest block freed so far, up to 32 MB,
and the trim threshold with it), so a young process pays page faults, one per 4 KB page, for the
same temporaries again and again. On the duck, a trial worker's first chunk of 1,024 ARMAR-III
trials took 86,000 minor faults, 0.13-0.15 s of system time and 2.22-2.26 s; with the limits
below 18,000, 0.03-0.09 s and 2.04-2.05 s. A one-core process of 2,048 ARMAR-III and 2,048
franka trials: 0.975x the wall time (all five pairs faster), system time 1.04 -> 0.44 s, the same
peak memory. Fixed limits keep freed memory in the heap for the next pass; a process's peak
stays what its largest pass needs, but its resident memory no longer shrinks after it.

Python's collector runs a full pass once enough new objects have survived its younger ones, and a
full pass walks every tracked object of the process: in the trial bench's process, 241,000 (the
libraries', pandas' and the chain's), 0.13-0.15 s a pass, set off at random by the trials' own
objects (a worker's 1,024 returned results did it twice in six two-core runs of 2,048 jaw trials,
each then 0.13-0.15 s longer). :func:`objects_frozen` keeps those objects out of its passes.
"""

import contextlib
import ctypes
import gc

#: glibc's mallopt parameters (malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: blocks below it come from the heap: glibc's own ceiling for the threshold it raises itself
MMAP_THRESHOLD_BYTES = 32 << 20
#: free heap top kept rather than returned to the system
TRIM_THRESHOLD_BYTES = 1 << 30


def keep_freed_memory():
    """Set this process's malloc to keep freed memory for reuse (:data:`MMAP_THRESHOLD_BYTES`,
    :data:`TRIM_THRESHOLD_BYTES`); idempotent. Returns whether it could: True with glibc, False
    with a C library without ``mallopt`` (macOS) or one that refuses the values."""
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    mmap_set = mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
    trim_set = mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)
    return bool(mmap_set and trim_set)


@contextlib.contextmanager
def objects_frozen():
    """Inside, the garbage collector's passes skip every object alive on entry (``gc.freeze``);
    objects made inside are collected as before, and on exit the frozen ones go back to its
    oldest generation. A process that has frozen objects itself (a pool worker, a stage forked
    from :mod:`pipeline.stage_server`) is left as it is."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()

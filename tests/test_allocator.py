"""How the trial processes manage memory: the malloc limits the trial engine sets (freed temporaries
stay in the heap for the next pass) and the objects kept out of the garbage collector's passes."""

import gc
import subprocess
import sys
import weakref

# a closing pass's pattern: 8 temporaries of 4 MB filled, then freed, five times after a first
# pass; prints whether the limits were set and the minor page faults of the five passes
CHURN = """
import resource, sys
import numpy as np
from pipeline.allocator import keep_freed_memory

kept = keep_freed_memory() if sys.argv[1] == "keep" else None

def faults():
    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt

def one_pass():
    arrays = [np.ones(1 << 19) for _ in range(8)]
    del arrays

one_pass()
before = faults()
for _ in range(5):
    one_pass()
print(kept, faults() - before)
"""


def _churn(mode):
    # a fresh process: a used one has raised its own thresholds already
    output = subprocess.run([sys.executable, "-c", CHURN, mode], capture_output=True, text=True, check=True).stdout
    kept, faults = output.split()
    return kept, int(faults)


def test_kept_memory_is_reused_without_page_faults_where_glibcs_defaults_fault_it_in_again():
    pages = 5 * 8 * (4 << 20) // 4096  # what the five passes touch
    kept, faults = _churn("keep")
    assert kept == "True" and faults < 0.01 * pages
    # the control: by default the freed heap top is trimmed and its pages faulted in again
    kept, faults = _churn("default")
    assert kept == "None" and faults > 0.2 * pages


class _Node:
    pass


def _tracked(value):
    """Whether ``value`` is in one of the collector's generations (not frozen)."""
    return any(found is value for found in gc.get_objects())


def test_objects_alive_on_entry_are_out_of_the_collectors_passes_and_new_ones_are_collected():
    from pipeline.allocator import objects_frozen

    assert gc.get_freeze_count() == 0, "the test process froze objects before the test"
    old = []
    with objects_frozen():
        assert gc.get_freeze_count() > 0 and not _tracked(old)
        cycle = _Node()
        cycle.self = cycle  # garbage only a pass of the collector finds
        gone = weakref.ref(cycle)
        del cycle
        gc.collect()
        assert gone() is None
    assert gc.get_freeze_count() == 0 and _tracked(old)


def test_a_process_that_froze_objects_itself_keeps_them_frozen():
    from pipeline.allocator import objects_frozen

    assert gc.get_freeze_count() == 0, "the test process froze objects before the test"
    old = []
    gc.freeze()
    try:
        # frozen objects can still die (the count falls), but none is added or let go
        frozen = gc.get_freeze_count()
        young = []
        with objects_frozen():
            assert gc.get_freeze_count() <= frozen and _tracked(young)
        assert 0 < gc.get_freeze_count() <= frozen and not _tracked(old) and _tracked(young)
    finally:
        gc.unfreeze()

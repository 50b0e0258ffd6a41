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

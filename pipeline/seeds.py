"""The run's random streams, one function per stream, each named for what it draws and made from
params ``seed`` (an int) alone, so that a stream does not depend on which others a run uses.

The algorithms take the generators these return (or, for the per-trial checks, seed
sequences); nothing else in the project derives a stream from the run's seed. The derivations are
part of every artefact downstream: changing one changes the run's results.
"""

import zlib

import numpy as np


def surface_samples(seed):
    """Generator of an object's surface samples (stage ``sample``; the concavity stage's
    concavities and filled object, each from a fresh one)."""
    return np.random.default_rng(seed)


def trial_spheres(seed):
    """Generator of the spheres whose candidates a hand tries (fresh per hand and planner: the
    same spheres whatever other hands run)."""
    return np.random.default_rng(seed)


def baseline(seed):
    """Generator of a hand's surface-normal baseline candidates (fresh per hand)."""
    return np.random.default_rng(seed + 1000)


def _hand_key(hand_name):
    return zlib.crc32(hand_name.encode())


def check_group(seed, hand_name, planner_number, count):
    """(sample seed, list of ``count`` per-trial seeds), numpy SeedSequences, of the ``check``
    stage for one hand's trials of one planner (its number in the planners' order): the sample
    of trials checked, and each trial's own noise (its position among those trials), so a
    trial's check does not depend on which others are checked."""
    group = np.random.SeedSequence([seed, _hand_key(hand_name), planner_number])
    sample, trials = group.spawn(2)
    return sample, trials.spawn(count)


def ablation_sample(seed):
    """Generator of the ablation's capped sample of each planner's candidates."""
    return np.random.default_rng([seed, 2000])


def ablation_order(seed, hand_name, planner_number):
    """Generator of the order in which the ablation's physics check takes one hand's candidates
    of one planner (the same order for every variant)."""
    return np.random.default_rng([seed, _hand_key(hand_name), planner_number])


def shown_normals(seed):
    """Generator of the surface normals a recording draws (at most a few thousand)."""
    return np.random.default_rng(seed)

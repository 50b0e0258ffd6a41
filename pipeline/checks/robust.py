"""Robust force closure: the probability that a grasp stays force closure under the errors a
robot makes (Dex-Net's robust epsilon).

Each trial is repeated ``samples`` times through the same trial engine
(:class:`pipeline.trial.engine.GraspEngine`), its candidate moved by a random pose error (the
grasp point by a Gaussian of ``pose_sigma_m`` per axis, the hand's orientation by a rotation
vector of ``angle_sigma_rad`` per axis, both P_d and P_o turned by it) and each copy graded with
its own friction coefficient (``mu`` plus a Gaussian of ``mu_sigma``, at least 0). The result
per trial: ``robust_fc``, the fraction of copies that are force closure, and
``robust_epsilon``, their mean epsilon (0 for a copy without force closure).

Randomness: one :class:`numpy.random.SeedSequence` per trial (spawned by the caller from the
run's seed), so a trial's copies do not depend on which other trials share its batch or worker.
"""

import numpy as np
from scipy.spatial.transform import Rotation


def perturbed_candidates(grasp, approach, orient, seeds, *, samples, pose_sigma_m, angle_sigma_rad, mu, mu_sigma):
    """``samples`` noisy copies of each of n candidates.

    Parameters
    ----------
    grasp, approach, orient : (n, 3) float
        P_g (m), P_d and P_o (unit vectors), object frame.
    seeds : sequence of n numpy.random.SeedSequence
        One per candidate.
    samples : int
    pose_sigma_m, angle_sigma_rad, mu_sigma : float
        Standard deviations of the grasp point's error per axis (m), of the orientation error's
        rotation vector per axis (rad) and of the friction coefficient.
    mu : float
        The nominal friction coefficient.

    Returns
    -------
    grasp, approach, orient : (n * samples, 3) float
        The copies, candidate by candidate (copy k of candidate i at row i * samples + k).
    mu : (n * samples,) float
        Each copy's friction coefficient, at least 0.
    """
    grasp, approach, orient = (np.asarray(value, np.float64).reshape(-1, 3) for value in (grasp, approach, orient))
    if len(seeds) != len(grasp):
        raise ValueError(f"seeds: one per candidate, got {len(seeds)} for {len(grasp)}")
    # each candidate's own stream: its 7 draws per copy, in a fixed order
    draws = np.array([np.random.default_rng(seed).standard_normal((samples, 7)) for seed in seeds]).reshape(-1, 7)
    turn = Rotation.from_rotvec(angle_sigma_rad * draws[:, 3:6])
    moved_grasp = np.repeat(grasp, samples, axis=0) + pose_sigma_m * draws[:, :3]
    moved_approach = turn.apply(np.repeat(approach, samples, axis=0))
    moved_orient = turn.apply(np.repeat(orient, samples, axis=0))
    return moved_grasp, moved_approach, moved_orient, np.maximum(mu + mu_sigma * draws[:, 6], 0.0)


def robust_force_closure(
    engine,
    grasp,
    approach,
    orient,
    preshapes,
    seeds,
    *,
    samples=16,
    pose_sigma_m=0.005,
    angle_sigma_rad=0.05,
    mu_sigma=0.1,
):
    """Robust force closure of n candidates (see the module docstring).

    Parameters
    ----------
    engine : pipeline.trial.engine.GraspEngine
        The hand and object; its settings (``mu``, cone edges, torsional friction) are the
        nominal ones.
    grasp, approach, orient : (n, 3) float
    preshapes : (n,) preshape names (None: the hand's default)
    seeds : sequence of n numpy.random.SeedSequence
    samples, pose_sigma_m, angle_sigma_rad, mu_sigma
        As :func:`perturbed_candidates`.

    Returns
    -------
    robust_fc : (n,) float in [0, 1]
    robust_epsilon : (n,) float
    """
    settings = engine.settings
    moved_grasp, moved_approach, moved_orient, mus = perturbed_candidates(
        grasp,
        approach,
        orient,
        seeds,
        samples=samples,
        pose_sigma_m=pose_sigma_m,
        angle_sigma_rad=angle_sigma_rad,
        mu=settings.mu,
        mu_sigma=mu_sigma,
    )
    results = engine.run(
        moved_grasp, moved_approach, moved_orient, list(np.repeat(np.asarray(preshapes, object), samples)), mus
    )
    return robust_summary(results, samples)


def robust_summary(results, samples):
    """``robust_fc`` and ``robust_epsilon`` (n,) of n candidates from their copies' trials: list
    of n * samples TrialResult, candidate by candidate (as :func:`perturbed_candidates` orders
    them), each graded at its own friction coefficient (:meth:`GraspEngine.run`'s ``mu``). A
    copy counts as force closure by its outcome; its epsilon is 0 without (the engine's)."""
    closed = np.array([result.outcome == "force_closure" for result in results], bool)
    epsilon = np.array([result.epsilon for result in results], np.float64)
    return closed.reshape(-1, samples).mean(axis=1), epsilon.reshape(-1, samples).mean(axis=1)

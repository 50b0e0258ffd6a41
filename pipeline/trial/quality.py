"""Ferrari-Canny epsilon (L1) grasp quality from contact points and normals.

Each contact's Coulomb friction cone is linearised by ``edges`` edge forces of unit normal
component and tangential length ``mu`` (half-angle ``atan(mu)``; Simox's generator uses 45 deg
whatever ``mu`` is). Each edge force f at contact p gives the wrench ``(f, (p - center) x f /
torque_scale)``; the grasp's epsilon is the distance from the ORIGIN of wrench space (not the
hull's centroid) to the nearest facet of the wrenches' convex hull, and 0 unless the origin is
strictly inside (force closure).

The nearest facet is found without building the whole hull, which in 6D has thousands of facets
for a hundred wrenches: a polytope of a few wrenches is grown until its nearest facet has no
wrench beyond it. A polytope inside the whole hull is never farther from the origin than the
whole one's facets, and a facet with no wrench beyond it supports the whole hull, so that facet's
distance is the whole hull's epsilon, exactly (to rounding). The polytope grows by one wrench at
a time (:func:`pipeline.trial.expanding_hull.nearest_facet`, 9-10x faster than Qhull on the engine's
grasps); where it meets a degenerate facet, Qhull's hulls of a few extreme wrenches are grown
instead, several wrenches a round (:func:`_nearest_facet`).

Torque is divided by ``torque_scale`` (metres) so that it is comparable with force; GraspIt and
Dex-Net use the object's largest radius about its centre of mass, which the caller passes along
with ``center`` (the centre of mass). Epsilon is then dimensionless and independent of the object's
size and placement. The cone's spin about its normal follows a fixed tangent basis, so rotating a
whole grasp can change epsilon slightly: it stays between the unrotated grasp's epsilon with
``mu cos(pi / edges)`` and with ``mu / cos(pi / edges)``.

References
----------
Ferrari, C. and Canny, J. (1992). Planning optimal grasps. ICRA, 2290-2295.
Miller, A. T. and Allen, P. K. (1999). Examples of 3D grasp quality computations. ICRA.
Duff, T. et al. (2017). Building an orthonormal basis, revisited. JCGT 6(1).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.spatial import ConvexHull, QhullError

from ..arrays import unit_rows
from ..tol import tol
from ..validate import as_points
from .expanding_hull import nearest_facet

GROW_FACETS = 8  # facets whose farthest wrench joins the grown hull per round
FACET_BLOCK = 64  # facets projected at once, nearest first, until the rest cannot matter
# Without pre-merging (Q0) Qhull is 2-3x faster in 6D and the facet offsets are the same; when
# it reports a precision error, co-planar cone edges of symmetric grasps (box pads, rings of
# fingers) need merging (Qx), sometimes wide merges (Q12); joggle (QJ, error ~1e-9 relative) is
# the last resort, so a good grasp is never scored 0 for it
QHULL_OPTIONS = ("Q0", "Qx", "Qx Q12", "QJ")


@dataclass(frozen=True)
class Quality:
    """Ferrari-Canny quality of one grasp.

    Attributes
    ----------
    epsilon : float
        Distance from the origin to the nearest facet of the wrench hull; 0 unless force closure.
    volume : float
        6D volume of the wrench hull (GraspIt's volume quality); 0 when the wrenches span fewer
        than 6 dimensions, NaN unless asked for (it needs the whole hull).
    force_closure : bool
        Whether the origin is strictly inside the hull (``epsilon > 0``).
    """

    epsilon: float
    volume: float
    force_closure: bool


def _check_cone(mu, edges):
    if mu < 0:
        raise ValueError(f"mu must be >= 0, got {mu}")
    if edges < 3:
        raise ValueError(f"edges must be >= 3, got {edges}")


def friction_cone(normals, mu=0.5, edges=8):
    """Edge forces of the linearised friction cones.

    Parameters
    ----------
    normals : (n, 3) float
        Inward contact normals (the direction the finger pushes); normalised here.
    mu : float
        Coulomb friction coefficient, >= 0; the cone's half-angle is ``atan(mu)`` radians.
    edges : int
        Edges per cone, >= 3.

    Returns
    -------
    (n, edges, 3) float64
        Edge k is ``n + mu (cos(2 pi k / edges) t1 + sin(2 pi k / edges) t2)``: unit normal
        component, tangential length ``mu``; (t1, t2, n) right-handed, by Duff et al. (2017).
    """
    _check_cone(mu, edges)
    normals = unit_rows(as_points("normals", normals, allow_empty=True))
    return _wrenches(normals, normals, float(mu), int(edges), 1.0, 0.0)[:, :edges, :3]


def contact_wrenches(points, normals, *, mu=0.5, edges=8, torque_scale=1.0, torsional_friction=0.0, center=None):
    """Wrenches of the friction-cone edges (and, for soft fingers, the torsional limits).

    Parameters
    ----------
    points : (n, 3) float
        Contact points, metres, object frame.
    normals : (n, 3) float
        Inward contact normals, object frame; normalised here.
    mu, edges
        See :func:`friction_cone`.
    torque_scale : float
        Length dividing torques, metres, > 0 (e.g. the object's largest radius).
    torsional_friction : float
        Soft-finger torsional friction gamma, metres, >= 0: the largest torque about the normal
        per unit normal force. 0 is a point contact with friction.
    center : (3,) float, optional
        Torque reference, metres, object frame (the centre of mass); defaults to the origin.

    Returns
    -------
    (n, k, 6) float64
        ``(force, torque / torque_scale)`` rows; k = ``edges``, or ``edges + 2`` with torsional
        friction, the extra two being force n with torque ``(p - center) x n +- gamma n``.
    """
    _check_cone(mu, edges)
    if torque_scale <= 0:
        raise ValueError(f"torque_scale must be > 0, got {torque_scale}")
    if torsional_friction < 0:
        raise ValueError(f"torsional_friction must be >= 0, got {torsional_friction}")
    points = as_points("points", points, allow_empty=True)
    normals = unit_rows(as_points("normals", normals, allow_empty=True))
    if len(points) != len(normals):
        raise ValueError(f"points and normals differ in length: {len(points)} != {len(normals)}")
    arm = points - (np.zeros(3) if center is None else np.asarray(center, dtype=np.float64))
    return _wrenches(arm, normals, float(mu), int(edges), float(torque_scale), float(torsional_friction))


@njit(cache=True)
def _wrenches(arms, normals, mu, edges, torque_scale, gamma):
    """(n, k, 6) wrenches of unit inward ``normals`` (n, 3) at lever ``arms`` (n, 3) from the
    torque reference; see :func:`contact_wrenches`. Scalar loops: a grasp's few contacts."""
    count = len(normals)
    extra = 2 if gamma > 0 else 0
    wrenches = np.empty((count, edges + extra, 6))
    for contact in range(count):
        x, y, z = normals[contact, 0], normals[contact, 1], normals[contact, 2]
        # Duff et al.'s branchless basis: continuous except across z = 0
        sign = 1.0 if z >= 0 else -1.0
        a = -1.0 / (sign + z)
        b = x * y * a
        first = (1 + sign * x * x * a, sign * b, -sign * x)
        second = (b, sign + y * y * a, -y)
        for edge in range(edges + extra):
            force = wrenches[contact, edge, :3]
            if edge < edges:
                angle = 2.0 * np.pi * edge / edges
                cos, sin = np.cos(angle), np.sin(angle)
                for axis in range(3):
                    force[axis] = normals[contact, axis] + mu * (cos * first[axis] + sin * second[axis])
            else:
                force[:] = normals[contact]
            ax, ay, az = arms[contact, 0], arms[contact, 1], arms[contact, 2]
            torque = (ay * force[2] - az * force[1], az * force[0] - ax * force[2], ax * force[1] - ay * force[0])
            spin = 0.0 if edge < edges else (gamma if edge == edges else -gamma)
            for axis in range(3):
                wrenches[contact, edge, 3 + axis] = (torque[axis] + spin * normals[contact, axis]) / torque_scale
    return wrenches


def _hull(wrenches):
    """Qhull's hull of (n, 6) wrenches, or None when every option fails."""
    for options in QHULL_OPTIONS:
        try:
            return ConvexHull(wrenches, qhull_options=options)
        except QhullError:
            continue
    return None


def _supports(wrenches, equations, distance):
    """The hull facets (indices, in order of ``distance``, stable) whose support can set the
    smallest one, the wrenches' projections on their normals (n, k) and their supports (k,).

    A facet's support is at least its own distance (its vertices are wrenches), so once the
    smallest support found is below the next facet's distance, the farther facets can change
    neither that minimum nor which facets lie below it: they are never projected (a hull of
    hundreds of wrenches has thousands of facets, nearly all of them far)."""
    order = np.argsort(distance, kind="stable")
    parts, upper, done = [], np.inf, 0
    while done < len(order) and distance[order[done]] < upper:
        block = order[done : done + FACET_BLOCK]
        parts.append(wrenches @ equations[block, :-1].T)
        upper = min(upper, parts[-1].max(axis=0).min())
        done += len(block)
    along = np.concatenate(parts, axis=1)
    return order[:done], along, along.max(axis=0)


def _nearest_facet(wrenches):
    """Signed distance from the origin to the nearest facet of the hull of (n, 6) full-rank
    ``wrenches`` (negative when the origin is outside), or None when Qhull fails."""
    axes = np.concatenate([np.eye(6), -np.eye(6)])
    # the extremes along the axes: growing from fewer, larger hulls was slower (measured)
    chosen = np.unique((wrenches @ axes.T).argmax(axis=0))
    if len(chosen) < 7:  # a 6D hull needs 7 points; the rounds only add more
        chosen = np.union1d(chosen, np.setdiff1d(np.arange(len(wrenches)), chosen)[: 7 - len(chosen)])
    while True:
        hull = _hull(wrenches[chosen])
        if hull is None:
            return None
        # equations rows are [unit normal, offset] with normal . x + offset <= 0 inside
        distance = -hull.equations[:, -1]
        # the small hull's epsilon bounds the whole one's from below, the whole one's support
        # along any unit direction from above (and a support <= 0 puts the origin outside)
        facets, along, support = _supports(wrenches, hull.equations, distance)
        lower, upper = distance.min(), support.min()
        if upper <= tol.hull_inside or upper - lower <= tol.hull_beyond:
            return float(min(lower, upper))
        # the nearest facets below the upper bound get their farthest wrench (the nearest one is
        # among them: its support is at least the upper bound, so a wrench lies beyond it); a
        # few per round gave the smallest hulls (measured: 8 of them, 25 % faster than all)
        wanted = np.flatnonzero((support - distance[facets] > tol.hull_beyond) & (distance[facets] < upper))
        wanted = wanted[:GROW_FACETS]  # facets are in order of distance
        grown = np.union1d(chosen, along[:, wanted].argmax(axis=0))
        if len(grown) == len(chosen):  # a joggled (QJ) hull's facets can miss its own points
            return None
        chosen = grown


def epsilon_quality(
    points, normals, *, mu=0.5, edges=8, torque_scale=1.0, torsional_friction=0.0, center=None, volume=False
):
    """Ferrari-Canny epsilon (L1) of a grasp; see :func:`contact_wrenches` for the parameters.
    ``volume``: also the hull's volume, from the whole hull, which then gives epsilon too (many
    times slower; the same epsilon to Qhull's rounding).

    Returns
    -------
    Quality
        Zero epsilon and volume for no contact, one contact or wrenches spanning fewer than
        6 dimensions (a flat hull, e.g. two point contacts).
    """
    wrenches = contact_wrenches(
        points,
        normals,
        mu=mu,
        edges=edges,
        torque_scale=torque_scale,
        torsional_friction=torsional_friction,
        center=center,
    )
    none = Quality(0.0, 0.0, False)
    if len(wrenches) < 2:  # one contact's cone never holds the origin inside
        return none
    wrenches = wrenches.reshape(-1, 6)
    # a hull needs a full-dimensional point set: check the affine rank before growing one
    spread = np.linalg.svd(wrenches - wrenches.mean(axis=0), compute_uv=False)
    if len(wrenches) < 7 or spread[5] <= tol.rank * spread[0]:
        return none
    distance = None if volume else nearest_facet(wrenches)  # a repeated wrench costs it nothing
    if distance is None:
        # for Qhull (a degenerate facet, or the volume), each wrench once in the contacts'
        # order: a lexicographically sorted input makes Qhull's incremental construction hit
        # precision errors (42 of 50 random grasps without pre-merging)
        _, first = np.unique(np.round(wrenches, tol.wrench_decimals), axis=0, return_index=True)
        wrenches = wrenches[np.sort(first)]
        if not volume:
            distance = _nearest_facet(wrenches)
    if distance is None:  # the volume asked for, or a small hull failed: the whole hull decides
        whole = _hull(wrenches)
        if whole is None:
            return none
        distance = -whole.equations[:, -1].max()
    inside = distance > tol.hull_inside
    return Quality(float(distance) if inside else 0.0, float(whole.volume) if volume else float("nan"), bool(inside))

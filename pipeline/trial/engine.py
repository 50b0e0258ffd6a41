"""Grasp trials (stage ``simulate``, paper IV), many candidates advancing together.

A trial is kinematic, as in the paper's OpenRAVE grasper: the object is its exact triangle mesh
(:mod:`pipeline.geometry.mesh_query`), the hand its URDF's kinematic tree and collision shapes
(:mod:`pipeline.hands.kinematics`), every distance one measure (:mod:`pipeline.trial.proximity`). Per
candidate (P_g, P_d, P_o, preshape):

1. place the hand: grasp centre at P_g, approach axis along P_d, wrap axis along P_o, open in
   the preshape;
2. retreat along -P_d in ``retract_step_m`` steps until the hand is clear of the object (no link
   point inside the mesh, no mesh vertex inside a link), jumping over the steps where a link
   point found inside is still inside (its exact ray along the retreat has not left the mesh);
   not clear within ``retract_max_m``: ``collision``;
3. move along +P_d in steps of at most ``approach_step_m`` (larger while the measured clearance
   allows) until the first link is within ``contact_tolerance_m``, from wherever the retreat
   left the hand (the placement itself when it was clear) and on past the placement by up to
   ``approach_max_m`` (OpenRAVE's and GraspIt's approach to contact; so where the hand's grasp
   centre lies on it decides only where the search starts). A hand that travels the whole
   bound without touching missed the object: ``no_contact``, fingers not closed (OpenRAVE drops
   such a plan). The paper's Simox port skipped this step: ``approach_to_contact`` false closes
   where the retreat left the hand;
4. close every finger at once, its joints moving by their coupling ratios (a negative ratio
   closes toward the lower limit; URDF mimic joints follow their leader), by conservative
   advancement: no point of a link moves farther than that link's distance to the object less
   half the tolerance, so nothing tunnels. A link within the tolerance that closing presses
   into the object (a touching point's velocity against the object's normal, by more than
   :attr:`pipeline.tol.Tolerances.sliding` of its speed) stops every joint
   that moves it; joints beyond it close on (the Barrett breakaway), and a link touching on its
   back, which closing moves away, goes on. A finger stops on ``contact``, at
   its joint ``limit``, or at the ``max_close_steps`` cap (outcome ``step_cap``);
5. contacts (:mod:`pipeline.trial.contacts`), measured finer than the closing steps
   (``contact_point_spacing_m``: the link edges' points and the object's crease points), and
   the Ferrari-Canny epsilon (:mod:`pipeline.trial.quality`),
   torque scaled by the object's largest distance from its centre of mass (GraspIt, Dex-Net).

Outcomes: ``force_closure``, ``no_force_closure``, ``no_contact``, ``collision``, ``step_cap``,
``error`` (a candidate that cannot be placed: a non-finite or parallel P_d, P_o). A programming
error raises. Every trial is computed row by row of the batch's arrays, so results do not depend
on the batch size or the number of worker processes.
"""

import gc
import pickle
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.spatial.transform import Rotation

from ..allocator import keep_freed_memory
from ..errors import BadInputError
from ..geometry.mass import torque_reference
from ..geometry.mesh_query import ObjectMesh
from ..hands.kinematics import base_poses, hand_model, link_poses, point_velocities
from ..threads import on_one_blas_thread
from ..tol import tol
from .contacts import region_corners
from .proximity import collides, measure
from .quality import epsilon_quality

OUTCOMES = ("force_closure", "no_force_closure", "no_contact", "collision", "step_cap", "error")
STOPS = ("contact", "limit", "step_cap", "none")
#: the outcomes of trials that end with the hand closed on the object (what the checks grade)
CLOSED = ("force_closure", "no_force_closure")


@dataclass(frozen=True)
class TrialResult:
    """One trial: outcome, quality, where the hand went and why each finger stopped.

    ``retract_m``: how far back along -P_d from its placement the hand closed (the retreat less
    the approach; negative past the placement); ``approach_m``: how far it came on along +P_d
    after the retreat; ``base_*``: the URDF base
    frame's pose after the approach; ``joint_positions``: closed actuated joints (the hand's
    ``limits`` order); ``touched``: names of the links in contact; ``finger_stops``: per finger,
    one of :data:`STOPS`; ``contact_links``: per contact, the link's index in the hand model."""

    outcome: str
    epsilon: float = 0.0
    retract_m: float = float("nan")
    approach_m: float = float("nan")
    base_position: tuple = (float("nan"),) * 3
    base_orientation: tuple = (float("nan"),) * 4
    joint_positions: tuple = ()
    close_steps: int = 0
    touched: tuple = ()
    finger_stops: tuple = ()
    contact_points: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    contact_normals: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))
    contact_links: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    message: str = ""


def trial_settings(settings=None, **overrides):
    """The :class:`pipeline.params.SimulateParams` a trial runs with: ``settings`` (the defaults
    when None) with the fields ``overrides`` replaced."""
    import dataclasses

    from ..params import SimulateParams

    return dataclasses.replace(SimulateParams() if settings is None else settings, **overrides)


def object_mesh(surface, settings, grid=None):
    """The :class:`ObjectMesh` of ``surface`` that trials with ``settings`` (SimulateParams) query:
    its distance grid and the feature points at their spacings (``grid``: as ObjectMesh takes it)."""
    return ObjectMesh(
        surface.vertices,
        surface.faces,
        grid_cells=settings.grid_cells,
        edge_spacing=settings.link_point_spacing_m,
        contact_edge_spacing=settings.contact_point_spacing_m,
        grid=grid,
    )


def _shifted(poses, offsets, direction):
    """Link poses (n, L, 4, 4) translated by ``-offsets[:, None] * direction`` (n, 3)."""
    moved = poses.copy()
    moved[:, :, :3, 3] -= (offsets[:, None] * direction)[:, None, :]
    return moved


def check_simulable(surface):
    """Refuse, in one line naming the file, an object without a closed mesh (a point cloud)."""
    if not len(surface.faces):
        raise BadInputError(
            f"{surface.source}: a point cloud has no surface to try grasps on; give a closed "
            "mesh (for a scan: reconstruct one, e.g. open3d's Poisson reconstruction)"
        )


class GraspEngine:
    """Runs grasp trials of one hand on one object; see the module docstring.

    Parameters
    ----------
    surface : SurfaceSamples
        The object: its mesh (``vertices``, ``faces``) must be closed.
    hand : Hand
    settings : SimulateParams, optional
        How trials are run (the ``simulate`` params; their defaults when None).
    mesh : ObjectMesh, optional
        The object as :func:`object_mesh` builds it from ``surface`` and these settings, to share
        one between engines (built here when None).
    **overrides
        Fields of ``settings`` to replace (``approach_to_contact=False``).
    """

    def __init__(self, surface, hand, settings=None, *, mesh=None, **overrides):
        self.settings = trial_settings(settings, **overrides)
        self.hand = hand
        spacing = self.settings.link_point_spacing_m
        self.model = hand_model(hand, spacing=spacing)
        # the closed hands' contacts from finer points on the same edges (and the same links)
        refine = int(np.ceil(spacing / self.settings.contact_point_spacing_m - 1e-9))
        self.contact_model = hand_model(hand, spacing=spacing, refine=refine)
        self.mesh = object_mesh(surface, self.settings) if mesh is None else mesh
        self.centre, self.torque_scale = torque_reference(self.mesh.vertices, self.mesh.faces)
        self.near = max(self.settings.near_m, self.settings.contact_tolerance_m)
        #: metres the hand may come on past its placement (-1: the hand's largest graspable diameter)
        self.approach_max = (
            hand.max_graspable_diameter if self.settings.approach_max_m == -1 else self.settings.approach_max_m
        )
        #: seconds spent in each step of the trials run so far (the bench's breakdown)
        self.seconds = dict.fromkeys(("place", "retreat", "approach", "closing", "contacts"), 0.0)
        # each closing pass frees and allocates the same temporaries again: keep them in the heap
        keep_freed_memory()

    def _lap(self, step, start):
        now = time.perf_counter()
        self.seconds[step] += now - start
        return now

    def trial(self, grasp_point, approach, orient, preshape=None):
        """One trial (see :meth:`run`)."""
        return self.run([grasp_point], [approach], [orient], [preshape])[0]

    @on_one_blas_thread  # OpenBLAS's helpers would spin on the cores the trial processes fill
    def run(self, grasp, approach, orient, preshapes, mu=None):
        """Trials of the candidates (n, 3) ``grasp`` (P_g), ``approach`` (P_d), ``orient`` (P_o),
        metres and unit vectors in the object frame, with ``preshapes`` (n,) names (None: the
        hand's default), each graded at its friction coefficient ``mu`` (n,) (default the
        settings' ``mu``; the robust check's noisy copies have their own). Returns a list of n
        :class:`TrialResult`."""
        grasp, approach, orient = (np.asarray(value, np.float64).reshape(-1, 3) for value in (grasp, approach, orient))
        count = len(grasp)
        results = [None] * count
        with np.errstate(invalid="ignore", divide="ignore"):
            approach = approach / np.linalg.norm(approach, axis=1, keepdims=True)
            side = np.linalg.norm(np.cross(approach, orient), axis=1)
        valid = (
            np.isfinite(grasp).all(axis=1)
            & np.isfinite(approach).all(axis=1)
            & np.isfinite(orient).all(axis=1)
            & (side > tol.parallel)
        )
        for number in np.flatnonzero(~valid):
            results[number] = TrialResult("error", message="candidate has a non-finite or zero P_d, or P_o along P_d")
        rows = np.flatnonzero(valid)
        if not len(rows):
            return results
        model = self.model
        start = time.perf_counter()
        names = np.asarray(preshapes, dtype=object)[rows]
        shapes = {name: [self.hand.preshape(name)[joint] for joint in model.joints] for name in set(names)}
        q = np.array([shapes[name] for name in names], dtype=np.float64).reshape(len(rows), len(model.joints))
        base = base_poses(self.hand, grasp[rows], approach[rows], orient[rows])
        placed = link_poses(model, base, q)
        start = self._lap("place", start)
        retreat = self._retreat(placed, approach[rows])
        start = self._lap("retreat", start)
        clear = np.isfinite(retreat)
        for number in rows[~clear]:
            results[number] = TrialResult("collision")
        rows, q, base, placed = rows[clear], q[clear], base[clear], placed[clear]
        retreat, direction = retreat[clear], approach[rows]
        final = self._approach(placed, direction, retreat)
        start = self._lap("approach", start)
        base[:, :3, 3] -= np.where(np.isfinite(final), final, -self.approach_max)[:, None] * direction
        missed = np.isnan(final)
        for number, pose, joints, way in zip(rows[missed], base[missed], q[missed], retreat[missed]):
            results[number] = self._missed(pose, joints, way)
        rows, q, base, final, retreat = (value[~missed] for value in (rows, q, base, final, retreat))
        q, stops, steps = self._close(base, q)
        start = self._lap("closing", start)
        closed = self._grade_closed(
            base, q, stops, steps, final, retreat - final, None if mu is None else np.asarray(mu, np.float64)[rows]
        )
        for number, result in zip(rows, closed):
            results[number] = result
        self._lap("contacts", start)
        return results

    @on_one_blas_thread
    def replay(self, base, joints):
        """Grade hands already closed, as :meth:`run` grades a trial once its fingers stopped:
        the contacts of the hand at exactly this configuration, then the quality.

        Parameters
        ----------
        base : (n, 4, 4) float
            The hand's URDF base frame in the object frame (T_object_base, metres): an exported
            grasp's transform, or :func:`pipeline.outputs.export.closed_poses` of trials (the pose the
            trial closed at, bit for bit; one built from its ``base_q*`` quaternion can be a
            rounding off, enough to change a contact at the edge of the tolerance).
        joints : (n, J) float
            Actuated joint values (rad or m) in ``hand_model(hand).joints`` order (the hand's
            ``limits`` order, the trials' ``joints`` column).

        Returns
        -------
        list of n TrialResult
            Outcome ``force_closure``, ``no_force_closure`` or ``no_contact`` and its epsilon;
            every finger's stop is ``contact`` (a replay cannot tell a joint limit), and
            ``retract_m``, ``approach_m`` are NaN (the hand did not move).
        """
        model = self.model
        base = np.asarray(base, np.float64).reshape(-1, 4, 4)
        q = np.asarray(joints, np.float64).reshape(len(base), len(model.joints))
        stops = np.zeros((len(base), model.fingers), np.int64)  # STOPS[0]: contact
        unknown = np.full(len(base), np.nan)
        return self._grade_closed(base, q, stops, np.zeros(len(base), np.int64), unknown, unknown)

    def _grade_closed(self, base, q, stops, steps, retract, approach, mu=None):
        """The :class:`TrialResult` of each closed hand: base poses (n, 4, 4), joints (n, J),
        finger ``stops`` (n, F) indices into :data:`STOPS`, closing ``steps`` (n,), and the
        ``retract`` and ``approach`` (n,) metres recorded with it; graded at the friction
        coefficients ``mu`` (n,) (default the settings')."""
        model = self.model
        poses = link_poses(model, base, q)
        # the closed hands' touching pairs, measured all at once; exact up to the tolerance is
        # all they need (a link farther than it touches nothing)
        links = np.flatnonzero(model.link_radius > 0)
        owner = np.repeat(np.arange(len(base)), len(links))
        distance, touches = measure(
            self.mesh,
            self.contact_model,
            poses,
            owner,
            np.tile(links, len(base)),
            near=self.settings.contact_tolerance_m,
            tolerance=self.settings.contact_tolerance_m,
            features=self.mesh.contact_features,
            capped=True,
        )
        distance = distance.reshape(len(base), len(links))
        order = np.argsort(touches.pair, kind="stable")
        pair, points, normals = touches.pair[order], touches.points[order], touches.normals[order]
        starts = np.searchsorted(pair, np.arange(len(base) + 1) * len(links))
        quaternions = Rotation.from_matrix(base[:, :3, :3]).as_quat()
        found = [slice(starts[position], starts[position + 1]) for position in range(len(base))]
        return [
            self._score(
                distance[position],
                pair[found[position]] - position * len(links),
                points[found[position]],
                normals[found[position]],
                base[position],
                quaternions[position],
                q[position],
                stops[position],
                steps[position],
                float(retract[position]),
                float(approach[position]),
                self.settings.mu if mu is None else float(mu[position]),
            )
            for position in range(len(base))
        ]

    def _retreat(self, placed, direction):
        """(n,) the smallest multiple of ``retract_step_m`` that leaves each hand clear, inf if none."""
        step, limit = self.settings.retract_step_m, self.settings.retract_max_m
        found = np.full(len(placed), np.inf)
        steps = np.zeros(len(placed), np.int64)
        pending = np.arange(len(placed))
        while len(pending):
            offset = steps[pending] * step
            moved = _shifted(placed[pending], offset, direction[pending])
            hit, depth = collides(self.mesh, self.model, moved, along=-direction[pending])
            found[pending[~hit]] = offset[~hit]
            # offsets that leave a link point certainly inside are skipped, not tried
            steps[pending] += np.maximum(1, np.ceil(depth / step - 1e-9)).astype(np.int64)
            pending = pending[hit & (steps[pending] * step <= limit + 1e-12)]
        return found

    def _distances(self, poses, wanted):
        """(n, L) distance of each wanted link (bool (n, L)) to the object, inf elsewhere."""
        rows, links = np.nonzero(wanted)
        distance = np.full(wanted.shape, np.inf)
        distance[rows, links] = measure(self.mesh, self.model, poses, rows, links, near=self.near)
        return distance

    def _approach(self, placed, direction, retreat):
        """(n,) offsets along -P_d (m, negative past the placement) where each hand, coming on
        along +P_d from ``retreat``, first has a link within the tolerance; NaN where none is
        after ``approach_max`` past the placement (a miss). ``retreat`` itself without
        ``approach_to_contact`` (the paper's Simox port)."""
        tolerance, step = self.settings.contact_tolerance_m, self.settings.approach_step_m
        offset = retreat.copy()
        if not self.settings.approach_to_contact:
            return offset
        farthest = -self.approach_max
        pending = np.arange(len(offset))
        wanted = np.broadcast_to(self.model.link_radius > 0, (len(placed), len(self.model.links)))
        while len(pending):
            gap = self._distances(_shifted(placed[pending], offset[pending], direction[pending]), wanted[pending]).min(
                axis=1
            )
            going = gap > tolerance
            room = offset[pending] - farthest
            at_bound = room <= 1e-9  # float steps can stop an ulp short of it
            offset[pending[going & at_bound]] = np.nan
            going &= ~at_bound
            # a move no longer than the clearance less the tolerance keeps every link clear; one
            # approach step (<= the tolerance, by the params' check) is safe from above it
            move = np.minimum(np.maximum(step, np.floor((gap - tolerance) / step) * step), room)
            offset[pending[going]] -= move[going]
            pending = pending[going]
        return offset

    def _missed(self, base, q, retreat):
        """The ``no_contact`` :class:`TrialResult` of a hand that came on ``approach_max`` past its
        placement with no link within the tolerance; ``base`` (4, 4) where it ended, ``q`` (J,)
        its open joints, ``retreat`` (m) how far it had backed out first."""
        return TrialResult(
            "no_contact",
            retract_m=-self.approach_max,
            approach_m=float(retreat + self.approach_max),
            base_position=tuple(map(float, base[:3, 3])),
            base_orientation=tuple(map(float, Rotation.from_matrix(base[:3, :3]).as_quat())),
            joint_positions=tuple(map(float, q)),
            finger_stops=("none",) * self.model.fingers,
            message=f"approach passed the object: no link within the contact tolerance {self.approach_max:g} m past the placement",
        )

    def _close(self, base, q):
        """Close every finger from ``q`` (n, J); returns the closed q, the per-finger stops
        (n, F) indices into :data:`STOPS` and the steps taken (n,)."""
        model, tolerance = self.model, self.settings.contact_tolerance_m
        count = len(q)
        q = q.copy()
        direction = np.sign(model.closing)
        at_limit = np.where(direction > 0, q >= model.upper, q <= model.lower)
        active = (direction != 0) & ~at_limit
        by_contact = np.zeros_like(active)
        fingers = model.finger[:, None] == np.arange(model.fingers)[None, :]  # (J, F)
        speed = np.abs(model.closing)[:, None] * model.lever  # (J, L) m per unit closing
        steps = np.zeros(count, np.int64)
        for _ in range(self.settings.max_close_steps):
            rows = np.flatnonzero(active.any(axis=1))
            if not len(rows):
                break
            steps[rows] += 1
            poses = link_poses(model, base[rows], q[rows])
            wanted = (active[rows].astype(float) @ model.moves) > 0
            pairs, links = np.nonzero(wanted & (model.link_radius > 0))
            distance = np.full(wanted.shape, np.inf)
            distance[pairs, links] = measure(self.mesh, model, poses, pairs, links, near=self.near, capped=True)
            # a link within the tolerance stops its joints where closing presses it into the
            # object; one touching on its back, which closing moves away, goes on (OpenRAVE and
            # GraspIt stop a joint on the collision its motion would make). Its touching pairs
            # are the contacts' own, finer points: at the closing points' 3 mm a pad's edge
            # touching a curved tip tilts into it by 1 deg where the 1 mm points say 3 deg
            touching = distance[pairs, links] <= tolerance
            pairs, links = pairs[touching], links[touching]
            _, touches = measure(
                self.mesh,
                self.contact_model,
                poses,
                pairs,
                links,
                near=tolerance,
                tolerance=tolerance,
                features=self.mesh.contact_features,
                capped=True,
            )
            owner, link = pairs[touches.pair], links[touches.pair]
            velocity = point_velocities(model, poses, owner, link, touches.points, active[rows][owner])
            into = np.einsum("ij,ij->i", velocity, touches.normals) < -tol.sliding * np.linalg.norm(velocity, axis=1)
            stopped, q[rows], still = _closing_step(
                distance,
                owner[into],
                link[into],
                active[rows],
                q[rows],
                model.moves,
                model.finger,
                speed,
                model.closing,
                model.lower,
                model.upper,
                self.near,
                tolerance,
            )
            by_contact[rows] |= stopped
            active[rows] = still
        per_finger = lambda mask: (mask.astype(float) @ fingers) > 0  # noqa: E731
        stops = np.where(per_finger(active), 2, np.where(per_finger(by_contact), 0, 1))
        stops = np.where(fingers.any(axis=0)[None, :], stops, 3)
        return q, stops, steps

    def _score(self, distance, pair, points, normals, base, quaternion, q, stops, steps, retract, approach, mu):
        """The :class:`TrialResult` of one closed hand from its measure: ``distance`` (G,) of each
        link with geometry, and the touching ``pair`` (t,) (index among those links), object
        ``points`` (t, 3) and ``normals`` (t, 3); ``base`` (4, 4) its base pose, ``quaternion``
        (4,) the same rotation; ``mu`` the friction coefficient it is graded at."""
        model, settings = self.model, self.settings
        pose = dict(
            retract_m=retract,
            approach_m=approach,
            base_position=tuple(map(float, base[:3, 3])),
            base_orientation=tuple(map(float, quaternion)),
            joint_positions=tuple(map(float, q)),
            close_steps=int(steps),
            finger_stops=tuple(STOPS[stop] for stop in stops),
        )
        links = np.flatnonzero(model.link_radius > 0)
        touched = links[distance <= settings.contact_tolerance_m]
        if (stops == 2).any():
            return TrialResult("step_cap", touched=tuple(model.links[link] for link in touched), **pose)
        bounds = np.flatnonzero(np.diff(pair, prepend=-1)) if len(pair) else np.zeros(0, np.int64)
        regions = [
            (links[pair[start]], points[start:end], normals[start:end])
            for start, end in zip(bounds, list(bounds[1:]) + [len(pair)])
        ]
        return grade(regions, model, settings, centre=self.centre, torque_scale=self.torque_scale, mu=mu, **pose)


@njit(cache=True)
def _closing_step(distance, owner, link, active, q, moves, finger, speed, closing, lower, upper, near, tolerance):
    """One pass of :meth:`GraspEngine._close` after its measures, for r hands: ``distance`` (r, L)
    of their links (inf where not measured), the (t,) ``owner`` hand and ``link`` of each touching
    point that closing presses into the object, the ``active`` joints (r, J) and ``q`` (r, J).
    Returns the joints those points stop (r, J), the new q (r, J) and the joints still closing
    after it (r, J): each finger advanced as far as its links' room allows, clipped at the
    limits. ``moves`` (J, L), ``finger`` (J,) (-1: none), ``speed`` (J, L) m per unit closing,
    ``closing``, ``lower``, ``upper`` (J,): the hand model's. Every float is the one of the numpy
    expressions it replaced (their few dozen calls a pass cost more than their arithmetic)."""
    hands, joints, links, fingers = q.shape[0], q.shape[1], distance.shape[1], finger.max() + 1
    pressing = np.zeros((hands, links), np.bool_)
    for touch in range(len(owner)):
        pressing[owner[touch], link[touch]] = True
    stopped = np.zeros((hands, joints), np.bool_)
    moving = active.copy()
    new = np.empty_like(q)
    for hand in range(hands):
        for joint in range(joints):
            if active[hand, joint]:
                for part in range(links):
                    if pressing[hand, part] and moves[joint, part]:
                        stopped[hand, joint] = True
                        moving[hand, joint] = False
                        break
        # per finger and link, metres moved per unit of the finger's closing parameter
        motion = np.zeros((fingers, links))
        for joint in range(joints):
            if moving[hand, joint] and finger[joint] >= 0:
                for part in range(links):
                    motion[finger[joint], part] += speed[joint, part]
        advance = np.full(fingers, np.inf)
        for part in range(links):
            sharing = 0  # fingers moving the link
            for number in range(fingers):
                sharing += motion[number, part] > 0
            # distances capped at ``near``: beyond it the engine knows only a bound, and a step
            # sized by it would make where a finger stops hang on the bound's slack
            room = max(min(distance[hand, part], near) - tolerance / 2, tolerance / 2) / max(sharing, 1)
            for number in range(fingers):
                if motion[number, part] > 0:
                    advance[number] = min(advance[number], room / motion[number, part])
        for joint in range(joints):
            change = 0.0
            if moving[hand, joint]:
                share = 0.0
                if finger[joint] >= 0 and np.isfinite(advance[finger[joint]]):
                    share = advance[finger[joint]]
                change = closing[joint] * share
            # every joint clipped, as numpy's clip with array bounds does (a bound where not past it)
            value = q[hand, joint] + change
            value = value if value > lower[joint] else lower[joint]
            new[hand, joint] = value if value < upper[joint] else upper[joint]
            if moving[hand, joint] and (
                new[hand, joint] >= upper[joint] if closing[joint] > 0 else new[hand, joint] <= lower[joint]
            ):
                moving[hand, joint] = False
    return stopped, new, moving


def grade(regions, model, settings, *, centre, torque_scale, mu=None, **pose):
    """The :class:`TrialResult` of a closed hand from its touching pairs.

    Parameters
    ----------
    regions : list of (int, (k, 3) float, (k, 3) float)
        Per touching link: its index in ``model``, the object points (m) and the object's
        outward unit normals of its touching pairs; merged here (:func:`region_corners`).
        Without ``settings.palm_contacts`` the palm's (link 0) are dropped first, and a hand
        that touched with its palm alone is ``no_contact``.
    model : HandModel
    settings : SimulateParams
    centre : (3,) float
        The object's centre of mass (m), the torque reference.
    torque_scale : float
        Length (m) dividing torques.
    mu : float, optional
        The friction coefficient (default ``settings.mu``).
    **pose
        The other :class:`TrialResult` fields (where the hand closed, joints, stops).
    """
    if not settings.palm_contacts:
        regions = [region for region in regions if region[0] != 0]
    if not regions:
        return TrialResult("no_contact", **pose)
    points, normals, owners = [], [], []
    for link, found, outward in regions:
        keep = region_corners(
            found, outward, coplanar_deg=settings.coplanar_deg, max_corners=settings.max_link_contacts
        )
        points.append(found[keep])
        normals.append(outward[keep])
        owners.append(np.full(len(keep), link))
    points, normals, owners = np.concatenate(points), np.concatenate(normals), np.concatenate(owners)
    quality = epsilon_quality(
        points,
        -normals,
        mu=settings.mu if mu is None else mu,
        edges=settings.cone_edges,
        torque_scale=torque_scale,
        torsional_friction=settings.torsional_friction_m,
        center=centre,
    )
    return TrialResult(
        "force_closure" if quality.force_closure else "no_force_closure",
        quality.epsilon,
        touched=tuple(model.links[link] for link in np.unique(owners)),
        contact_points=points,
        contact_normals=normals,
        contact_links=owners,
        **pose,
    )


# A worker process's engines, one per hand, built once by the caller of the pool and sent to each
# worker (pipeline.trial.protocol runs the pool, pipeline.pool forks its workers from a server that
# has imported this module).
_WORKER = {}


def kernels_loaded():
    """Whether this process has the engine's compiled kernels loaded: it has run a trial, or is
    a pool worker (forked from a server that loaded them, :mod:`pipeline.kernel_cache`)."""
    return bool(_closing_step.signatures)


def start_worker(engines):
    """Set up this process to run trials with ``engines`` ({hand number: GraspEngine})."""
    _WORKER.update(engines=engines)


def start_pool_worker():
    """Set up a worker process of a pool: the objects so far (the imported libraries'), and each
    call's engines once loaded (:func:`run_chunk`), are moved out of the garbage collector's
    reach: a full collection walked them all, about 0.12 s, between one chunk and the next. Its
    malloc keeps freed memory (:func:`pipeline.allocator.keep_freed_memory`), as the caller's does."""
    gc.freeze()
    keep_freed_memory()


def _engines(copy):
    """This process's engines: a pool worker's from ``copy`` (:func:`run_chunk`), loaded at its
    first chunk of the call that wrote it, the previous call's let go first."""
    if copy is not None and _WORKER.get("copy") != copy:
        _WORKER.clear()
        with open(copy[0], "rb") as file:
            _WORKER.update(engines=pickle.load(file), copy=copy)
        gc.freeze()
    return _WORKER["engines"]


def run_chunk(copy, hand_number, grasp, approach, orient, preshapes, mu=None):
    """Trials of the candidates ``grasp``, ``approach``, ``orient`` (n, 3), ``preshapes`` and
    ``mu`` (n,) (:meth:`GraspEngine.run`) with hand ``hand_number`` of the engines ``copy``: None
    for this process's own (:func:`start_worker`), else (path, call) of the file they are pickled
    in and the call that wrote it (a pool's worker may run several calls' chunks). Returns their
    results, and when they started and ended (``time.perf_counter`` seconds, one clock for every
    process of the machine on Linux; a worker's first chunk of a call starts once it has loaded
    the engines)."""
    engines = _engines(copy)
    start = time.perf_counter()
    if not len(grasp):
        return [], start, start
    results = engines[hand_number].run(grasp, approach, orient, preshapes, mu)
    return results, start, time.perf_counter()


def stop_worker():
    """Forget this process's engines."""
    _WORKER.clear()

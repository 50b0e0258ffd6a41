"""Ferrari-Canny epsilon against answers known analytically or by an independent method.

"SLSQP" below means: epsilon minimises the hull's support function h(u) = max_i w_i . u over
unit u in R^6, found from the best of 1e5 random directions refined by scipy's SLSQP on
``min t s.t. W u <= t, |u| = 1``; it agreed with the Qhull value to 1e-12 or better.
"""

import itertools

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from pipeline.errors import BadInputError
from pipeline.trial.quality import Quality, contact_wrenches, epsilon_quality, friction_cone

A = 0.02  # half-width of the box between two antipodal fingers, metres
OCTAGON = np.cos(np.pi / 8)  # inradius / circumradius of the 8-edge cone's cross-section
NONE = Quality(0.0, 0.0, False)


def antipodal(a=A, height=0.0):
    """Contacts at (a, 0, 0) and (-a, 0, height) with inward normals -x and +x."""
    return np.array([[a, 0, 0], [-a, 0, height]]), np.array([[-1.0, 0, 0], [1.0, 0, 0]])


def four_faces(a=A):
    """Point contacts at the centres of the four side faces of a cube of half-width a."""
    points = np.array([[a, 0, 0], [-a, 0, 0], [0, a, 0], [0, -a, 0]])
    return points, -points / a


def three_ring(r=0.03):
    """Three point contacts 120 deg apart on the equator of a cylinder of radius r."""
    angle = 2 * np.pi * np.arange(3) / 3
    points = np.c_[r * np.cos(angle), r * np.sin(angle), np.zeros(3)]
    return points, -points / r


def box_pads(w=0.01, d=0.015, x=0.02):
    """Two parallel-jaw pads, each touching with its 4 corners (2w by 2d) at x = +-x."""
    corners = np.array([[0, s * w, t * d] for s in (-1, 1) for t in (-1, 1)])
    points = np.r_[corners + [x, 0, 0], corners - [x, 0, 0]]
    return points, np.repeat([[-1.0, 0, 0], [1.0, 0, 0]], 4, axis=0)


def random_rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q * np.linalg.det(q)


def soft_antipodal_epsilon(a, torque_scale, gamma, mu):
    """Closed-form epsilon of two antipodal soft fingers at +-a, 8-edge cones.

    With s = a/L, g = gamma/L, coordinates (fx, fy, fz, ty, tz, tx): contact 1's edges are
    (-1, mu c, mu s', 0, -s mu s', s mu c) and contact 2's (1, mu c, mu s', 0, s mu s', -s mu c)
    (c, s' = cos, sin of the edge angle), the torsion wrenches (-+1, 0, 0, 0, 0, +-g). For s = 1
    the change of coordinates sigma1 = (fy + tz)/sqrt2, delta1 = (fy - tz)/sqrt2, sigma2 =
    (fz - ty)/sqrt2, delta2 = (fz + ty)/sqrt2 is orthonormal and puts contact 1's octagon (radius
    m = sqrt2 mu) in the sigma plane at fx = -1 and contact 2's in the delta plane at fx = +1, so
    h(u) = max(-u0 + m' r1, u0 + m' r2, |u0| + g |u5|), m' = m cos(pi/8) at best (the octagon's
    inradius). epsilon = 1 / max |u| over h(u) <= 1; the bound is convex in u0, so the max is at
    u0 = 0 (r1 = r2 = 1/m', u5 = 1/g: |u|^2 = (L/gamma)^2 + 1/(mu cos(pi/8))^2) or at |u0| = 1
    (r = 2/m', u5 = 0: |u|^2 = 1 + 2/(mu cos(pi/8))^2). For s != 1 the two planes meet at cosine
    c0 = (1 - s^2)/(1 + s^2) and the same argument gives the terms below.
    The first term alone is 1/sqrt((L/gamma)^2 + 1/(mu cos(pi/8))^2), right only while torsion
    is weak (gamma/L below about 0.42 at mu = 0.5).
    """
    s, k = a / torque_scale, mu * OCTAGON
    inner = (torque_scale / gamma) ** 2 + 1 / (k * min(1.0, s)) ** 2
    outer = 1 + (1 + s * s) / (k * s) ** 2
    return 1 / np.sqrt(max(inner, outer))


# --- cones and wrenches ---------------------------------------------------------------------


@pytest.mark.parametrize("mu", [0.2, 0.5, 1.0])
@pytest.mark.parametrize("edges", [4, 8, 16])
def test_cone_half_angle_is_atan_mu(mu, edges, rng):
    normals = rng.normal(size=(5, 3)) * 3.0  # not unit: friction_cone normalises
    unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    cone = friction_cone(normals, mu, edges)
    assert cone.shape == (5, edges, 3)
    along = np.einsum("nkj,nj->nk", cone, unit)
    np.testing.assert_allclose(along, 1.0, atol=1e-12)
    tangential = cone - along[..., None] * unit[:, None]
    np.testing.assert_allclose(np.linalg.norm(tangential, axis=2), mu, atol=1e-12)
    angle = np.arccos(along / np.linalg.norm(cone, axis=2))
    np.testing.assert_allclose(angle, np.arctan(mu), atol=1e-12)
    # evenly spaced: consecutive tangential parts 2 pi / edges apart
    step = np.einsum("nkj,nkj->nk", tangential, np.roll(tangential, -1, axis=1)) / mu**2
    np.testing.assert_allclose(step, np.cos(2 * np.pi / edges), atol=1e-12)


def test_narrow_cone_is_not_45_degrees():
    """Simox builds 45 deg cones whatever mu is; mu = 0.2 must give atan(0.2) ~ 11.3 deg."""
    cone = friction_cone([[0.0, 0, 1]], 0.2, 8)
    angle = np.arccos(cone[0, :, 2] / np.linalg.norm(cone[0], axis=1))
    assert np.degrees(angle).max() < 11.4
    assert not np.allclose(angle, np.pi / 4)


def test_contact_wrenches_by_hand():
    """Contact at (a, 0, 0) + c pushing along -x: torque (p - c) x f = (0, -a fz, a fy)."""
    a, length, gamma, mu = 0.03, 0.06, 0.004, 0.5
    center = np.array([0.1, -0.2, 0.3])
    wrenches = contact_wrenches(
        [[a + 0.1, -0.2, 0.3]], [[-2.0, 0, 0]], mu=mu, torque_scale=length, torsional_friction=gamma, center=center
    )
    assert wrenches.shape == (1, 10, 6)
    force, torque = wrenches[0, :, :3], wrenches[0, :, 3:]
    np.testing.assert_allclose(force[:8, 0], -1.0)
    np.testing.assert_allclose(np.hypot(force[:8, 1], force[:8, 2]), mu)
    np.testing.assert_allclose(torque[:8], np.c_[np.zeros(8), -a * force[:8, 2], a * force[:8, 1]] / length, atol=1e-15)
    # torsion: force n = -x, torque +-gamma n (the arm is parallel to n)
    np.testing.assert_allclose(
        wrenches[0, 8:], [[-1, 0, 0, -gamma / length, 0, 0], [-1, 0, 0, gamma / length, 0, 0]], atol=1e-15
    )
    assert contact_wrenches([[a, 0, 0]], [[-1.0, 0, 0]]).shape == (1, 8, 6)


# --- analytic two-finger grasps -------------------------------------------------------------


def test_antipodal_point_contacts_are_not_force_closure():
    """Two point contacts cannot resist torque about their line (Nguyen 1988): rank 5, flat."""
    points, normals = antipodal()
    wrenches = contact_wrenches(points, normals, mu=0.5, torque_scale=A).reshape(-1, 6)
    assert np.linalg.matrix_rank(wrenches) == 5
    assert epsilon_quality(points, normals, mu=0.5, torque_scale=A) == NONE


@pytest.mark.parametrize(
    "length, gamma, mu",
    [
        (A, 0.005, 0.5),  # the weak-torsion branch: 1/sqrt((L/gamma)^2 + 1/(mu cos(pi/8))^2)
        (A, 0.001, 0.2),
        (A, 0.005, 1.0),
        (A, 0.02, 0.5),  # strong torsion: 1/sqrt(1 + 2/(mu cos(pi/8))^2)
        (A / 2, 0.005, 0.5),  # torque_scale below and above the lever arm
        (2 * A, 0.005, 0.5),
        (A / 2, 0.05, 0.5),
    ],
)
def test_antipodal_soft_fingers_match_closed_form(length, gamma, mu):
    points, normals = antipodal()
    quality = epsilon_quality(points, normals, mu=mu, torque_scale=length, torsional_friction=gamma, volume=True)
    assert quality.force_closure and quality.volume > 0
    assert quality.epsilon == pytest.approx(soft_antipodal_epsilon(A, length, gamma, mu), abs=1e-9)


def test_brief_formula_at_its_own_parameters():
    """a = L = 0.02, gamma = 0.005, mu = 0.5 -> 1/sqrt(16 + 1/(0.5 cos(pi/8))^2) = 0.2198663..."""
    points, normals = antipodal()
    quality = epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=0.005)
    expected = 1 / np.sqrt((A / 0.005) ** 2 + 1 / (0.5 * OCTAGON) ** 2)
    assert quality.epsilon == pytest.approx(expected, abs=1e-6)
    assert quality.epsilon == pytest.approx(0.219866306016, abs=1e-11)


def test_tolerances_are_overridable_where_used(monkeypatch):
    from pipeline.tol import tol

    points, normals = antipodal()
    assert epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=0.005).force_closure
    # its wrenches' smallest singular value is 0.11 x the largest (0.5 / 4.47): a rank tolerance
    # of 0.2 calls them flat, one of 0.1 does not
    monkeypatch.setattr(tol, "rank", 0.1)
    assert epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=0.005).force_closure
    monkeypatch.setattr(tol, "rank", 0.2)
    assert epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=0.005) == NONE


def test_antipodal_soft_fingers_rotation_invariant(rng):
    """The two cones' octagons lie in orthogonal planes, so their spin cannot change epsilon."""
    points, normals = antipodal()
    options = dict(mu=0.5, torque_scale=A, torsional_friction=0.005)
    expected = epsilon_quality(points, normals, **options).epsilon
    for _ in range(5):
        rotation, shift = random_rotation(rng), rng.normal(size=3) * 0.1
        moved = epsilon_quality(points @ rotation.T + shift, normals @ rotation.T, center=shift, **options)
        assert moved.epsilon == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("gamma", [0.005, 0.1])
def test_line_outside_the_cones_is_not_force_closure(gamma):
    """f1 = -f2 = f and torque balance (p1 - p2) x f = torsion along x force f parallel to
    p1 - p2 = (2a, 0, -h); with h / 2a = 0.75 > mu = 0.5 no such f lies in the cones, however
    large gamma is. The hull is full-dimensional, the origin just outside it."""
    points, normals = antipodal(height=1.5 * A)
    quality = epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=gamma, volume=True)
    assert quality.epsilon == 0.0 and not quality.force_closure
    assert quality.volume > 0
    # inside the cones (h / 2a = 0.4 < mu) the same fingers do hold
    points, normals = antipodal(height=0.8 * A)
    assert epsilon_quality(points, normals, mu=0.5, torque_scale=A, torsional_friction=gamma).epsilon > 0


# --- multi-finger grasps --------------------------------------------------------------------


@pytest.mark.parametrize(
    "grasp, length, expected",
    [
        (four_faces, A, 0.3204264174890872),  # SLSQP
        (three_ring, 0.03, 0.26903476269164944),  # SLSQP
        # Qhull 2020.2 raises a precision error on these coplanar pads with its default options;
        # the Q12 retry must still give the SLSQP value
        (box_pads, 0.02, 0.44194173824159244),
    ],
)
def test_point_contact_grasps_known_epsilon(grasp, length, expected):
    points, normals = grasp()
    quality = epsilon_quality(points, normals, mu=0.5, torque_scale=length, volume=True)
    assert quality.force_closure and quality.volume > 0
    assert quality.epsilon == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize("grasp", [four_faces, three_ring, box_pads])
def test_flipping_every_normal_keeps_epsilon(grasp):
    """Outward cones give the wrenches -W, whose hull is the mirror image: same epsilon.
    (A pulling grasp is as good as the pushing one; flipping all normals is no failure case.)"""
    points, normals = grasp()
    pushing = epsilon_quality(points, normals, torque_scale=0.03)
    pulling = epsilon_quality(points, -normals, torque_scale=0.03)
    assert pulling.epsilon == pytest.approx(pushing.epsilon, abs=1e-9) and pulling.force_closure


def test_contacts_on_one_face_are_not_force_closure():
    """Every wrench has fz = 1 > 0: the plane fz = 0 separates the origin from the hull."""
    points = np.array([[0.01, 0.01, -0.02], [-0.01, 0.01, -0.02], [0.01, -0.01, -0.02], [-0.01, -0.01, -0.02]])
    normals = np.tile([0.0, 0, 1], (4, 1))
    assert epsilon_quality(points, normals, torque_scale=0.02) == NONE
    assert epsilon_quality(points, normals, torque_scale=0.02, torsional_friction=0.01) == NONE


def test_no_or_one_contact():
    assert epsilon_quality(np.empty((0, 3)), np.empty((0, 3))) == NONE
    assert epsilon_quality([[A, 0, 0]], [[-1.0, 0, 0]], torsional_friction=0.01) == NONE


def test_epsilon_grows_with_mu():
    """A wider cone contains the narrower one, so the hull only grows."""
    points, normals = four_faces()
    eps = [epsilon_quality(points, normals, mu=mu, torque_scale=A).epsilon for mu in (0.2, 0.5, 1.0)]
    assert 0 < eps[0] < eps[1] < eps[2]


@pytest.fixture(params=["expanding", "qhull"])
def grown_by(request, monkeypatch):
    """Each grown-hull test runs twice: by the expanding polytope, then as if it had met a
    degenerate facet, by Qhull's grown hulls (its fallback)."""
    if request.param == "qhull":
        import pipeline.trial.quality as quality

        monkeypatch.setattr(quality, "nearest_facet", lambda wrenches: None)
    return request.param


@pytest.mark.parametrize("spread", [np.pi, np.pi / 2])
def test_grown_hull_gives_the_whole_hulls_epsilon(spread, rng, grown_by):
    """Many contacts (the engine's usual case): epsilon from the grown hull equals the nearest
    facet of Qhull's hull of every wrench; contacts within ``spread`` of a pole (a hemisphere) are
    often not force closure, which must agree too."""
    closures = []
    for _ in range(20):
        count = rng.integers(3, 25)
        polar = np.arccos(1 - (1 - np.cos(spread)) * rng.random(count))
        azimuth = 2 * np.pi * rng.random(count)
        outward = np.c_[np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)]
        points, normals = 0.03 * outward, -outward
        options = dict(mu=0.5, torque_scale=0.03, torsional_friction=0.0)
        wrenches = contact_wrenches(points, normals, **options).reshape(-1, 6)
        whole = -ConvexHull(wrenches).equations[:, -1].max()
        quality = epsilon_quality(points, normals, **options)
        assert quality.force_closure == (whole > 1e-12)
        assert quality.epsilon == pytest.approx(whole if whole > 1e-12 else 0.0, abs=1e-12)
        closures.append(quality.force_closure)
    # both verdicts are exercised: some grasps hold, and on a hemisphere some do not
    assert any(closures) and (spread == np.pi or not all(closures))


def test_supports_skip_only_facets_that_cannot_matter(rng):
    """The nearest-first projection gives the smallest support of every facet, and every facet
    below it, of a hull with thousands of facets, while projecting only a few of them."""
    from pipeline.trial.quality import _supports

    outward = rng.normal(size=(150, 3))
    outward /= np.linalg.norm(outward, axis=1, keepdims=True)
    wrenches = contact_wrenches(0.03 * outward, -outward, mu=0.5, torque_scale=0.03).reshape(-1, 6)
    hull = ConvexHull(wrenches[rng.choice(len(wrenches), 60, replace=False)])
    distance = -hull.equations[:, -1]
    facets, along, support = _supports(wrenches, hull.equations, distance)
    every = (wrenches @ hull.equations[:, :-1].T).max(axis=0)
    assert support.min() == every.min() and len(facets) < len(hull.equations) / 2  # 1280 of 3718 here
    below = np.flatnonzero(distance < every.min())
    assert set(below) <= set(facets) and np.array_equal(support, every[facets])
    assert np.all(np.diff(distance[facets]) >= 0)  # nearest first


def test_grown_hull_with_many_contacts_gives_the_whole_hulls_epsilon(rng, grown_by):
    for count in (40, 80):
        outward = rng.normal(size=(count, 3))
        outward /= np.linalg.norm(outward, axis=1, keepdims=True)
        points, normals = 0.03 * outward, -outward
        wrenches = contact_wrenches(points, normals, mu=0.5, torque_scale=0.03).reshape(-1, 6)
        whole = -ConvexHull(wrenches).equations[:, -1].max()
        quality = epsilon_quality(points, normals, mu=0.5, torque_scale=0.03)
        assert quality.force_closure and quality.epsilon == pytest.approx(whole, abs=1e-12)


def test_joggled_small_hulls_still_end(monkeypatch, rng):
    """Under Qhull's joggle (QJ, the last option) a small hull's facets can miss its own points
    by ~1e-9, so growing it may add nothing: epsilon then comes from the whole hull instead of
    looping (it did, on 16 of 60 of these grasps)."""
    import pipeline.trial.quality as quality

    monkeypatch.setattr(quality, "QHULL_OPTIONS", ("QJ",))
    monkeypatch.setattr(quality, "nearest_facet", lambda wrenches: None)  # Qhull's path
    for _ in range(30):
        outward = rng.normal(size=(rng.integers(3, 12), 3))
        outward /= np.linalg.norm(outward, axis=1, keepdims=True)
        options = dict(mu=0.5, torque_scale=0.03)
        wrenches = contact_wrenches(0.03 * outward, -outward, **options).reshape(-1, 6)
        exact = -ConvexHull(wrenches).equations[:, -1].max()
        joggled = epsilon_quality(0.03 * outward, -outward, **options).epsilon
        assert joggled == pytest.approx(max(exact, 0.0), abs=1e-6)


def test_volume_only_when_asked():
    points, normals = four_faces()
    assert np.isnan(epsilon_quality(points, normals, torque_scale=A).volume)
    whole = ConvexHull(contact_wrenches(points, normals, torque_scale=A).reshape(-1, 6))
    assert epsilon_quality(points, normals, torque_scale=A, volume=True).volume == pytest.approx(whole.volume)


# --- invariances ----------------------------------------------------------------------------


def test_translation_invariance(rng):
    points, normals = four_faces()
    expected = epsilon_quality(points, normals, torque_scale=A).epsilon
    shift = rng.normal(size=3)
    moved = epsilon_quality(points + shift, normals, torque_scale=A, center=shift)
    assert moved.epsilon == pytest.approx(expected, abs=1e-9)


def test_cube_symmetries_are_exact():
    """The 24 rotations of the cube map axis normals to axis normals and their tangent bases
    to bases 90 deg apart, so every 8-edge cone maps onto a cone of the same spin."""
    points, normals = four_faces()
    expected = epsilon_quality(points, normals, torque_scale=A).epsilon
    for order in itertools.permutations(range(3)):
        for signs in itertools.product((-1, 1), repeat=3):
            rotation = np.eye(3)[list(order)] * signs
            if np.linalg.det(rotation) > 0:
                moved = epsilon_quality(points @ rotation.T, normals @ rotation.T, torque_scale=A)
                assert moved.epsilon == pytest.approx(expected, abs=1e-9)


def test_random_rotation_stays_within_cone_spin_bounds(rng):
    """A random rotation spins each octagon about its normal. Octagon(mu) of any spin contains
    the disc of radius mu cos(pi/8), which contains octagon(mu cos(pi/8)) of any spin, and lies in
    the disc of radius mu inside octagon(mu / cos(pi/8)): epsilon is bracketed by those two."""
    points, normals = four_faces()
    low = epsilon_quality(points, normals, mu=0.5 * OCTAGON, torque_scale=A).epsilon
    high = epsilon_quality(points, normals, mu=0.5 / OCTAGON, torque_scale=A).epsilon
    for _ in range(5):
        rotation = random_rotation(rng)
        moved = epsilon_quality(points @ rotation.T, normals @ rotation.T, torque_scale=A).epsilon
        assert low - 1e-12 <= moved <= high + 1e-12


def test_scaling_the_grasp_and_its_lengths_keeps_epsilon():
    """Epsilon is dimensionless: scale points, center, torque_scale and gamma together."""
    points, normals = antipodal(height=0.5 * A)
    center = np.array([0.001, 0.002, 0.003])
    options = dict(mu=0.5, torque_scale=A, torsional_friction=0.005, center=center)
    expected = epsilon_quality(points, normals, **options).epsilon
    scaled = epsilon_quality(
        7 * points, normals, mu=0.5, torque_scale=7 * A, torsional_friction=7 * 0.005, center=7 * center
    )
    assert expected > 0 and scaled.epsilon == pytest.approx(expected, abs=1e-9)


# --- determinism, inputs, options -----------------------------------------------------------


def test_deterministic_and_inputs_not_modified():
    points, normals = box_pads()
    normals = normals * 2.0
    center = np.array([0.0, 0.001, 0.0])
    saved = points.copy(), normals.copy(), center.copy()
    first = epsilon_quality(points, normals, torque_scale=0.02, torsional_friction=0.002, center=center, volume=True)
    second = epsilon_quality(points, normals, torque_scale=0.02, torsional_friction=0.002, center=center, volume=True)
    assert first == second
    contact_wrenches(points, normals, center=center)
    friction_cone(normals)
    for before, after in zip(saved, (points, normals, center)):
        np.testing.assert_array_equal(before, after)


@pytest.mark.parametrize(
    "options, word",
    [
        (dict(mu=-0.1), "mu"),
        (dict(edges=2), "edges"),
        (dict(torque_scale=0.0), "torque_scale"),
        (dict(torsional_friction=-1e-3), "torsional_friction"),
    ],
)
def test_bad_options_raise_naming_the_value(options, word):
    points, normals = four_faces()
    with pytest.raises(ValueError, match=word):
        epsilon_quality(points, normals, **options)


def test_bad_shapes_raise():
    with pytest.raises(BadInputError, match="normals"):
        contact_wrenches(np.zeros((2, 3)), np.zeros((2, 2)))
    with pytest.raises(ValueError, match="differ"):
        contact_wrenches(np.zeros((2, 3)), np.ones((3, 3)))

"""The library's numerical tolerances, in one place (after trimesh's ``tol``).

Most decide rounding and degeneracy; a few are modelling thresholds too fine to tune per run
(``sliding``, ``smooth_half_rad``), each documented with why it has its value. They are not
params: each is an attribute of :data:`tol`, read when it is used, so that
``pipeline.tol.tol.rank = 1e-8`` overrides it for the process (trial worker processes start from
these values). Lengths are
metres; ``*_decimals`` are decimal places of rounding before points or planes are compared.
"""

from dataclasses import dataclass


@dataclass
class Tolerances:
    """See the module docstring; each field says where it is used."""

    rank: float = 1e-9
    """Wrenches whose smallest singular value is below this x the largest span less than 6D:
    epsilon 0 (:mod:`pipeline.trial.quality`)."""
    hull_inside: float = 1e-12
    """An origin nearer than this to a hull facet counts as on the hull: epsilon 0 (quality,
    :mod:`pipeline.trial.expanding_hull`)."""
    hull_beyond: float = 1e-10
    """A wrench must lie this far past a facet's plane to count as beyond it (quality's grown
    hulls, :mod:`pipeline.trial.expanding_hull`)."""
    hull_sliver: float = 1e-9
    """A polytope facet whose vertex is nearer than this x its edge's length to the span of the
    facet's other edges is a sliver: epsilon is then found with Qhull (:mod:`pipeline.trial.expanding_hull`)."""
    wrench_decimals: int = 12
    """Wrenches equal at this rounding are one (symmetric contacts only slow Qhull down)."""
    edge_tie_m: float = 1e-9
    """Link edges this much farther than the nearest still count as nearest, so that the contact
    normal at a link corner does not hang on rounding (:mod:`pipeline.trial.proximity`)."""
    border: float = 1e-4
    """A closest point whose smallest barycentric coordinate in its triangle is below this may
    lie on the triangle's edge or corner, where another triangle ties with it
    (:meth:`pipeline.geometry.mesh_query.ObjectMesh.on_border`; open3d answers in float32)."""
    sliding: float = 0.035
    """A touching point whose closing velocity points into the object by less than this
    fraction of its speed (sin 2 deg) slides past it and does not stop its link: a prismatic
    jaw's side face runs exactly along its motion, and a pad passing a smooth surface's facet
    seam meets it at the surface's own normal (:func:`pipeline.geometry.mesh_query.feature_contact_normals`),
    where a product of 1e-6 was the engine's or the reference's sampling, not a press
    (:mod:`pipeline.trial.engine`, :mod:`pipeline.trial.reference`)."""
    overlap_m: float = 1e-6
    """A mesh vertex deeper than this inside a link is a collision (proximity)."""
    point_decimals: int = 12
    """Link surface points, touching pairs and contact normals equal at this rounding are one
    (:mod:`pipeline.hands.kinematics`, :mod:`pipeline.trial.contacts`)."""
    plane_decimals: int = 9
    """Convex-piece face planes equal at this rounding are one face (kinematics)."""
    contact_merge_m: float = 1e-4
    """Touching points of one region closer than this are one contact (contacts)."""
    parallel: float = 1e-6
    """|P_d x P_o| below this: the candidate has no wrap direction (an ``error`` trial)."""
    pair_spread: float = 1e-12
    """A neighbourhood whose second PCA eigenvalue is below this x the first lies on a line: a
    ``pair`` (:mod:`pipeline.geometry.symmetry`)."""
    cap_planarity: float = 0.01
    """An open boundary loop is capped only if each of its vertices lies within this fraction of
    the loop's largest extent from its best-fit plane (0.1 mm on a 1 cm tube end;
    :mod:`pipeline.geometry.objects`)."""
    flat_volume: float = 1e-12
    """A mesh whose volume is below this x its bounding-box diagonal cubed is a flat sheet (objects)."""
    smooth_half_rad: float = 0.2617993877991494
    """15 deg: an object edge or corner whose normal cone is at most this wide each way is a facet
    seam of a smooth surface (faces within 30 deg, ``sample.sharp_angle_deg``'s default), where a
    contact pushes along the surface's normal (:func:`pipeline.geometry.mesh_query.feature_contact_normals`)."""
    crease_rad: float = 1e-6
    """Mesh edges whose faces meet at a larger angle are measured along their length
    (:mod:`pipeline.geometry.mesh_query`)."""
    straight_turn: float = 1e-12
    """A 2D hull turn (cross product) at most this x the points' extent squared is straight: the
    middle point is on an edge, not a corner (contact regions, :mod:`pipeline.trial.contacts`)."""
    grid_slack: float = 1e-6
    """Slack, as a fraction of a cell, added to the distance grid's bounds for open3d's float32
    distances (good to about 1e-7 of the object's size; mesh_query)."""
    cover_cell_m: float = 0.01
    """Largest cell of the spheres covering a hand link's convex piece (kinematics)."""


tol = Tolerances()

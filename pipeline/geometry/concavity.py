"""Concavities and the grasps that encompass them (stage ``concavity``; the paper's section V).

The paper's planner grasps a coffee cup by its handle and rim, "but no grasps that encompass the
concavity of the cup from the outside"; it suggests the medial axis transform of the concavity.
Here:

1. The object's concavities are the parts of its convex hull minus the object (manifold3d) of at
   least ``min_volume`` x the hull's volume.
2. A part counts when it opens through one flat mouth, as a container does: the part's faces on
   the hull's boundary (its opening) all lie within ``flat_mouth_deg`` of their mean normal. A
   handle's loop, the space under a table or around a neck opens on several sides or around a
   corner: filling it would put a grasp across empty space.
3. Each counted concavity gets its medial spheres through the project's own ``sample``,
   ``medial_axis`` and ``mat`` functions; its ``width`` is its largest sphere's diameter (how
   wide the hollow is), ``mouth_width`` the widest distance across its opening.
4. The filled object (object plus counted concavities) runs through ``sample``, ``medial_axis``,
   ``mat``, ``sphere_grid`` and ``classify`` with the object's params; its classified spheres
   whose centres lie inside a counted concavity are the ``encompassing`` spheres: grasps around
   the container's outside that the plain object's spheres (walls as plates) cannot give.

The ``candidates`` stage makes their candidates for a hand (sphere class ``encompassing``) when
the concavity is no wider than ``max_width_ratio`` x the hand's ``max_graspable_diameter``: a
vase's 17 cm hollow is too wide for both hands, so its neck is not grasped as if it were solid.
"""

from dataclasses import dataclass

import numpy as np

from .. import seeds
from ..artefacts import _Artefact, content_key
from ..errors import BadInputError
from .symmetry import Symmetry

#: the params sections the concavities and the filled object run with (the object's own)
SECTIONS = ("sample", "medial_axis", "mat", "sphere_grid", "classify")


@dataclass(frozen=True)
class Concavities(_Artefact):
    """The object's concavities and the encompassing spheres (``concavity.npz``).

    Per part of the hull minus the object of at least the minimum volume (c,): ``volume`` m^3,
    ``mouths`` (connected openings), ``flat`` (one mouth within ``flat_mouth_deg``), ``counted``
    (flat and filled), ``width`` m (diameter of its largest medial sphere; NaN where not
    counted), ``mouth_width`` m. The parts' solids: ``vertices`` (v, 3), ``faces`` (f, 3) and
    ``face_part`` (f,) into the parts.

    Per encompassing sphere (s,): the filled object's :class:`Symmetry` fields (``sphere_index``
    into the filled object's sphere grid, ``class_id``, ``rho``, ``eigenvalues``, ``axes``,
    ``cog``, ``neighbour_count``, ``centers``, ``radii``) and ``part``, its concavity;
    ``search_radius`` m of the filled object's classification; ``filled_spheres``, the filled
    object's classified spheres in all.
    """

    volume: np.ndarray
    mouths: np.ndarray
    flat: np.ndarray
    counted: np.ndarray
    width: np.ndarray
    mouth_width: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    face_part: np.ndarray
    sphere_index: np.ndarray
    class_id: np.ndarray
    rho: np.ndarray
    eigenvalues: np.ndarray
    axes: np.ndarray
    cog: np.ndarray
    neighbour_count: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    part: np.ndarray
    search_radius: float
    filled_spheres: int
    key: str

    KIND = "concavities"
    ARRAYS = {
        "volume": (np.float64, None),
        "mouths": (np.int64, None),
        "flat": (bool, None),
        "counted": (bool, None),
        "width": (np.float64, None),
        "mouth_width": (np.float64, None),
        "vertices": (np.float64, 3),
        "faces": (np.int64, 3),
        "face_part": (np.int64, None),
        **{name: Symmetry.ARRAYS[name] for name in Symmetry.ARRAYS},
        "part": (np.int64, None),
    }

    def __len__(self):
        return len(self.sphere_index)

    def spheres_for(self, max_diameter, max_width_ratio=1.0):
        """The encompassing spheres of the concavities no wider than ``max_width_ratio`` x
        ``max_diameter`` (m; a hand's ``max_graspable_diameter``), as a :class:`Symmetry`."""
        keep = self.width[self.part] <= max_width_ratio * max_diameter if len(self) else np.zeros(0, bool)
        return Symmetry(
            **{name: getattr(self, name)[keep] for name in Symmetry.ARRAYS},
            search_radius=self.search_radius,
            key=self.key,
        )


def _manifold(vertices, faces):
    import manifold3d

    mesh = manifold3d.Mesh(
        vert_properties=np.ascontiguousarray(vertices, np.float32), tri_verts=np.ascontiguousarray(faces, np.uint32)
    )
    return manifold3d.Manifold(mesh)


def _arrays(solid):
    mesh = solid.to_mesh()
    return np.asarray(mesh.vert_properties[:, :3], np.float64), np.asarray(mesh.tri_verts, np.int64)


def mouth_faces(vertices, faces, hull_scene, size):
    """(f,) bool: the faces of a part of the hull minus the object that lie on the hull's
    boundary (its opening): their centres within 1e-4 x ``size`` (m, the object's extent) of the
    hull (``hull_scene``, an open3d RaycastingScene of it; float32 throughout)."""
    import open3d

    centres = open3d.core.Tensor(vertices[faces].mean(axis=1).astype(np.float32))
    return hull_scene.compute_distance(centres).numpy() < 1e-4 * size


def mouth_shape(vertices, faces, mouth):
    """(mouths, largest angle (rad) of a mouth face from the mean normal of its mouth, widest
    distance (m) across a mouth) of the ``mouth`` (f,) faces of one part, mouths being their
    edge-connected groups."""
    import trimesh
    from scipy.spatial.distance import pdist

    part = trimesh.Trimesh(vertices, faces, process=False)
    adjacency = part.face_adjacency
    inside = mouth[adjacency[:, 0]] & mouth[adjacency[:, 1]]
    groups = trimesh.graph.connected_components(adjacency[inside], nodes=np.flatnonzero(mouth), min_len=1)
    normals, areas = part.face_normals, part.area_faces
    angle, width = 0.0, 0.0
    for group in groups:
        mean = (normals[group] * areas[group, None]).sum(axis=0)
        mean /= max(np.linalg.norm(mean), 1e-300)
        angle = max(angle, float(np.arccos(np.clip(normals[group] @ mean, -1.0, 1.0)).max()))
        corners = vertices[np.unique(faces[group])]
        corners = corners[:: max(1, len(corners) // 2000)]  # pdist is quadratic
        width = max(width, float(pdist(corners).max()) if len(corners) > 1 else 0.0)
    return len(groups), angle, width


def _pieces(vertices, faces, min_volume):
    """The vertex-connected pieces of a closed mesh of at least ``min_volume`` m^3, as (vertices,
    faces, volume m^3) tuples (manifold3d's ``decompose`` takes a minute on the thousands of
    slivers between a smooth object and its hull)."""
    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    if not len(faces):
        return []
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = scipy.sparse.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(len(vertices),) * 2)
    count, label = connected_components(graph, directed=False)
    owner = label[faces[:, 0]]
    corners = vertices[faces]
    volume = np.bincount(
        owner, np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2])) / 6.0, minlength=count
    )
    pieces = []
    for piece in np.flatnonzero(volume >= min_volume):
        mine = faces[owner == piece]
        used, local = np.unique(mine, return_inverse=True)
        pieces.append((vertices[used], local.reshape(-1, 3), float(volume[piece])))
    return pieces


def concavity_parts(vertices, faces, *, min_volume, flat_mouth_deg):
    """The parts of the hull minus the closed mesh (``vertices`` (v, 3) m, ``faces`` (f, 3)) of
    at least ``min_volume`` x the hull's volume, largest first: a list of dicts with
    ``vertices``, ``faces``, ``volume`` (m^3), ``mouths``, ``flat`` (one mouth whose faces lie
    within ``flat_mouth_deg`` of its mean normal) and ``mouth_width`` (m); and the object as a
    manifold3d solid."""
    import open3d

    solid = _manifold(vertices, faces)
    if solid.status().name != "NoError":
        raise BadInputError(f"the mesh is not a closed manifold solid ({solid.status().name})")
    hull = solid.hull()
    hull_vertices, hull_faces = _arrays(hull)
    hull_scene = open3d.t.geometry.RaycastingScene()
    hull_scene.add_triangles(
        open3d.core.Tensor(hull_vertices.astype(np.float32)), open3d.core.Tensor(hull_faces.astype(np.uint32))
    )
    size = float(np.ptp(hull_vertices, axis=0).max())
    parts = []
    for part_vertices, part_faces, volume in _pieces(*_arrays(hull - solid), min_volume * hull.volume()):
        mouth = mouth_faces(part_vertices, part_faces, hull_scene, size)
        mouths, angle, width = mouth_shape(part_vertices, part_faces, mouth)
        parts.append(
            dict(
                vertices=part_vertices,
                faces=part_faces,
                volume=volume,
                mouths=mouths,
                flat=bool(mouths == 1 and angle <= np.radians(flat_mouth_deg)),
                mouth_width=width,
            )
        )
    parts.sort(key=lambda part: -part["volume"])
    return parts, solid


def _samples(vertices, faces, rng, sample, name):
    """SurfaceSamples of a closed mesh with the ``sample`` params (a dict), drawn by ``rng``."""
    from .sampling import mesh_samples

    return mesh_samples(
        vertices,
        faces,
        count=sample["count"],
        rng=rng,
        sharp_angle_deg=sample["sharp_angle_deg"],
        source=name,
    )


def _spheres(surface, medial_axis, mat):
    from .mat import reconstruct
    from .medial_axis import medial_axis as find_axis

    return reconstruct(surface, find_axis(surface, **medial_axis), **mat)


def encompass(
    surface,
    *,
    enabled=True,
    min_volume=0.05,
    flat_mouth_deg=5.0,
    max_width_ratio=1.0,
    seed=0,
    sample=None,
    medial_axis=None,
    mat=None,
    sphere_grid=None,
    classify=None,
):
    """The ``concavity`` stage as a pure function (see the module docstring).

    Parameters
    ----------
    surface : SurfaceSamples
        The object (its closed mesh; a point cloud has no concavities here).
    enabled : bool
        False: no concavities, no encompassing spheres.
    min_volume : float
        Smallest concavity counted, x the convex hull's volume.
    flat_mouth_deg : float, degrees
    max_width_ratio : float
        Used by the ``candidates`` stage (:meth:`Concavities.spheres_for`); in the key only.
    seed : int
        Seed of the concavities' and the filled object's surface samples.
    sample, medial_axis, mat, sphere_grid, classify : dict
        Those stages' params (the object's own), applied to the concavities and the filled object.

    Returns
    -------
    Concavities
    """
    import dataclasses

    from ..params import ClassifyParams, MatParams, MedialAxisParams, SampleParams, SphereGridParams
    from .sphere_grid import build
    from .symmetry import classify as classify_spheres

    sections = {
        name: {**dataclasses.asdict(cls()), **(given or {})}
        for name, cls, given in (
            ("sample", SampleParams, sample),
            ("medial_axis", MedialAxisParams, medial_axis),
            ("mat", MatParams, mat),
            ("sphere_grid", SphereGridParams, sphere_grid),
            ("classify", ClassifyParams, classify),
        )
    }
    own = dict(enabled=enabled, min_volume=min_volume, flat_mouth_deg=flat_mouth_deg, max_width_ratio=max_width_ratio)
    key = content_key("concavity", {**own, "seed": seed, **sections}, surface.key)
    parts, solid = [], None
    if enabled and len(surface.faces):
        parts, solid = concavity_parts(
            surface.vertices, surface.faces, min_volume=min_volume, flat_mouth_deg=flat_mouth_deg
        )
    width = np.full(len(parts), np.nan)
    counted = [number for number, part in enumerate(parts) if part["flat"]]
    for number in counted:
        hollow = _samples(
            parts[number]["vertices"],
            parts[number]["faces"],
            seeds.surface_samples(seed),
            sections["sample"],
            "concavity",
        )
        width[number] = 2.0 * float(_spheres(hollow, sections["medial_axis"], sections["mat"]).radii.max())
    empty = {
        "sphere_index": np.zeros(0, np.int64),
        "class_id": np.zeros(0, np.int64),
        "rho": np.zeros(0),
        "eigenvalues": np.zeros((0, 3)),
        "axes": np.zeros((0, 9)),
        "cog": np.zeros((0, 3)),
        "neighbour_count": np.zeros(0, np.int64),
        "centers": np.zeros((0, 3)),
        "radii": np.zeros(0),
    }
    found, owner, search_radius, filled_spheres = empty, np.zeros(0, np.int64), 0.0, 0
    if counted:
        import manifold3d

        filled = manifold3d.Manifold.batch_boolean(
            [solid] + [_manifold(parts[number]["vertices"], parts[number]["faces"]) for number in counted],
            manifold3d.OpType.Add,
        )
        filled_vertices, filled_faces = _arrays(filled)
        whole = _samples(filled_vertices, filled_faces, seeds.surface_samples(seed), sections["sample"], "filled")
        symmetry = classify_spheres(
            build(_spheres(whole, sections["medial_axis"], sections["mat"]), **sections["sphere_grid"]),
            **sections["classify"],
        )
        search_radius, filled_spheres = symmetry.search_radius, len(symmetry)
        owner = np.full(len(symmetry), -1)
        for number in counted:
            owner[(owner < 0) & _inside(parts[number], symmetry.centers)] = number
        keep = owner >= 0
        found, owner = {name: getattr(symmetry, name)[keep] for name in empty}, owner[keep]
    sizes = [len(part["faces"]) for part in parts]
    offsets = np.cumsum([0] + [len(part["vertices"]) for part in parts])
    return Concavities(
        volume=np.array([part["volume"] for part in parts]),
        mouths=np.array([part["mouths"] for part in parts], np.int64),
        flat=np.array([part["flat"] for part in parts], bool),
        counted=np.isfinite(width),
        width=width,
        mouth_width=np.array([part["mouth_width"] for part in parts]),
        vertices=np.concatenate([part["vertices"] for part in parts]) if parts else np.zeros((0, 3)),
        faces=(
            np.concatenate([part["faces"] + offset for part, offset in zip(parts, offsets)])
            if parts
            else np.zeros((0, 3), np.int64)
        ),
        face_part=np.repeat(np.arange(len(parts)), sizes),
        **found,
        part=owner,
        search_radius=float(search_radius),
        filled_spheres=int(filled_spheres),
        key=key,
    )


def _inside(part, points):
    """(n,) bool: the (n, 3) ``points`` inside the part's closed solid."""
    from .mesh_query import ObjectMesh

    if not len(points):
        return np.zeros(0, bool)
    return ObjectMesh(part["vertices"], part["faces"], grid_cells=4).inside(points)

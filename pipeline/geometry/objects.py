"""Objects: resolve a source (file, built-in primitive, pybullet mesh), load and validate it.

A source string is one of

- ``primitive:NAME`` with shape keywords (metres; defaults in brackets): ``box`` (extents
  [0.10, 0.06, 0.02]), ``capsule`` (radius 0.02, height 0.10 between the cap centres),
  ``cylinder`` (radius 0.025, height 0.12), ``sphere`` (radius 0.04), ``torus``
  (major_radius 0.05, minor_radius 0.012), ``plate`` (extents [0.10, 0.10, 0.006]), and the
  procedural ``quadruped``, ``mug`` (radius 0.05) and others of :mod:`pipeline.geometry.procedural`;
- ``pybullet:RELPATH``: a mesh shipped in the installed ``pybullet_data`` package;
- a path to an OBJ/STL/PLY/OFF/GLB mesh, or a PLY point cloud with or without normals.

Validation (``validate_mesh``) rejects with one line naming the file: no triangles,
NaN/inf coordinates, open or non-manifold surfaces (after the hole repairs below), zero
volume, and sizes outside the accepted extent range (wrong units). Documented repairs:
duplicate vertices are merged, degenerate and duplicate faces dropped, small (triangle and
quad) holes filled, planar open ends capped (``cap_planar_holes``: e.g. the open tube ends of
the handle of pybullet's ``objects/mug.obj``; a :class:`RepairWarning` says so), inverted
winding flipped, and several bodies united into one solid with manifold3d.
"""

import re
import warnings
from pathlib import Path

import numpy as np
import trimesh

from ..errors import BadInputError, BadParamsError
from ..tol import tol

MESH_SUFFIXES = {".obj", ".stl", ".ply", ".off", ".glb", ".gltf"}


_PRIMITIVES = {
    "box": lambda extents=(0.10, 0.06, 0.02): trimesh.creation.box(extents=extents),
    "plate": lambda extents=(0.10, 0.10, 0.006): trimesh.creation.box(extents=extents),
    "capsule": lambda radius=0.02, height=0.10: trimesh.creation.capsule(height=height, radius=radius, count=[64, 256]),
    "cylinder": lambda radius=0.025, height=0.12: trimesh.creation.cylinder(radius=radius, height=height, sections=256),
    "sphere": lambda radius=0.04: trimesh.creation.icosphere(subdivisions=5, radius=radius),
    "torus": lambda major_radius=0.05, minor_radius=0.012: trimesh.creation.torus(
        major_radius=major_radius, minor_radius=minor_radius, major_sections=256, minor_sections=128
    ),
}


def pybullet_path(relative):
    """Absolute path of a file inside the installed ``pybullet_data`` package."""
    import pybullet_data

    return Path(pybullet_data.getDataPath()) / relative


class RepairWarning(UserWarning):
    """A repair that changed the shape of an input mesh (an open end capped): the mesh is used, but
    the user should check that it is the solid they meant."""


def natural_key(path):
    """Sort key of a path by its stem, numbers by value (``2`` before ``10``)."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.stem)]


def mesh_files(folder):
    """The folder (``pybullet:DIR`` resolved to the installed pybullet_data) and the mesh files
    under it, recursively, in natural order of their stems (``2`` before ``10``).

    Returns
    -------
    folder : Path
    files : list of (Path relative to folder, absolute resolved Path), never empty
    """
    folder = (
        pybullet_path(str(folder).removeprefix("pybullet:")) if str(folder).startswith("pybullet:") else Path(folder)
    )
    if not folder.is_dir():
        raise BadInputError(f"{folder}: not a folder")
    relatives = sorted(
        (
            path.relative_to(folder)
            for path in folder.rglob("*")
            if path.suffix.lower() in MESH_SUFFIXES and path.is_file()
        ),
        key=lambda path: (natural_key(path), str(path)),
    )
    if not relatives:
        raise BadInputError(f"{folder}: holds no mesh ({', '.join(sorted(MESH_SUFFIXES))})")
    return folder, [(relative, (folder / relative).resolve()) for relative in relatives]


def select_meshes(meshes, *, folder, only=None, limit=None):
    """The ``(name, path)`` pairs of ``meshes`` whose file stem is in ``only`` (every stem must
    match a file), then the first ``limit`` of them (order kept)."""
    if only is not None:
        wanted = {str(stem) for stem in only}
        missing = sorted(wanted - {path.stem for _, path in meshes})
        if missing:
            raise BadInputError(f"{folder}: no mesh named {', '.join(missing)}")
        meshes = [(name, path) for name, path in meshes if path.stem in wanted]
    if limit is not None:
        if limit < 1:
            raise BadParamsError(f"--limit must be at least 1, got {limit}")
        meshes = meshes[:limit]
    return meshes


def object_name(relative, prefix=""):
    """The params.yaml object name of the mesh file at ``relative`` (a path under the listed folder).

    The path's parts, suffix dropped, joined with ``-``; each part keeps ``[A-Za-z0-9_]`` (other
    characters, ``-`` included, become ``_``), so two files give one name only if their paths
    differ in those characters or the suffix. ``prefix`` goes in front; a name YAML would not
    read as that string (``1``, ``true``) gets ``mesh_`` in front. DVC takes ``-`` and ``_`` in
    the stage names it builds from these (``sample@NAME-1.0``).
    """
    import yaml

    parts = list(Path(relative).with_suffix("").parts)
    parts[0] = f"{prefix}{parts[0]}"
    name = "-".join(re.sub(r"\W", "_", part) for part in parts)
    if not name[:1].isalpha() or yaml.safe_load(name) != name:
        name = f"mesh_{name}"
    return name


def primitive(name, **shape):
    """Build a watertight primitive mesh (metres) by name; see the module docstring."""
    from .procedural import BUILDERS

    builders = {**_PRIMITIVES, **BUILDERS}
    if name not in builders:
        raise BadInputError(f"primitive:{name}: unknown primitive (known: {', '.join(builders)})")
    try:
        return builders[name](**shape)
    except TypeError as err:
        raise BadInputError(f"primitive:{name}: bad shape keywords {sorted(shape)} ({err})") from None


def load_source(source, *, scale=1.0, shape=None):
    """Load an object as ``('mesh', trimesh.Trimesh)`` or ``('cloud', points, normals_or_None)``.

    Parameters
    ----------
    source : str
        See the module docstring.
    scale : float
        Uniform factor applied to the coordinates (e.g. 0.001 for a mesh in millimetres).
    shape : dict, optional
        Keywords of a ``primitive:`` source.
    """
    if not (np.isfinite(scale) and scale > 0):
        raise BadInputError(f"{source}: scale must be a positive number, got {scale!r}")
    if source.startswith("primitive:"):
        mesh = primitive(source.removeprefix("primitive:"), **(shape or {}))
        mesh.apply_scale(scale)
        return ("mesh", mesh)
    path = pybullet_path(source.removeprefix("pybullet:")) if source.startswith("pybullet:") else Path(source)
    if not path.is_file():
        raise BadInputError(f"{path}: file not found")
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise BadInputError(
            f"{path}: unsupported format '{path.suffix}' (use one of {', '.join(sorted(MESH_SUFFIXES))})"
        )
    if path.stat().st_size == 0:
        raise BadInputError(f"{path}: file is empty")
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as err:  # noqa: BLE001 - any parser failure is a bad file for the user
        raise BadInputError(f"{path}: cannot be read as a mesh ({type(err).__name__}: {err})") from None
    if isinstance(loaded, trimesh.Scene):
        geometries = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
        if not geometries:
            raise BadInputError(f"{path}: holds no triangles")
        loaded = trimesh.util.concatenate(geometries)
    if isinstance(loaded, trimesh.PointCloud) or (
        isinstance(loaded, trimesh.Trimesh) and len(loaded.faces) == 0 and len(loaded.vertices)
    ):
        points, normals = _read_cloud(path)
        return ("cloud", points * scale, normals)
    if not isinstance(loaded, trimesh.Trimesh):
        raise BadInputError(f"{path}: holds no triangles (got {type(loaded).__name__})")
    loaded.apply_scale(scale)
    return ("mesh", loaded)


def _read_cloud(path):
    import open3d

    cloud = open3d.io.read_point_cloud(str(path))
    points = np.asarray(cloud.points, dtype=np.float64)
    normals = np.asarray(cloud.normals, dtype=np.float64) if cloud.has_normals() else None
    return points, normals


def check_size(points, *, name, min_extent, max_extent):
    """The bounding-box diagonal of ``points`` ((n, 3), metres); outside the range it is an error.

    A size outside ``[min_extent, max_extent]`` almost always means wrong units.
    """
    diagonal = float(np.linalg.norm(np.ptp(np.asarray(points), axis=0)))
    if not min_extent <= diagonal <= max_extent:
        raise BadInputError(
            f"{name}: bounding-box diagonal {diagonal:.4g} m is outside "
            f"[{min_extent:g}, {max_extent:g}] m: wrong units? (for a mesh in millimetres pass "
            "--scale 0.001, or set the object's scale in params.yaml)"
        )
    return diagonal


def validate_mesh(mesh, *, name, min_extent, max_extent):
    """Repair what is safe to repair and reject the rest; returns a new watertight Trimesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Never modified.
    name : str
        File or source named in error messages.
    min_extent, max_extent : float
        Accepted range of the bounding-box diagonal, metres.

    Raises
    ------
    BadInputError

    Warns
    -----
    RepairWarning
        When open ends were capped.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    if len(faces) == 0:
        raise BadInputError(f"{name}: holds no triangles")
    if faces.ndim != 2 or faces.shape[1] != 3:
        raise BadInputError(f"{name}: faces are not triangles (shape {faces.shape})")
    if not np.isfinite(vertices).all():
        raise BadInputError(f"{name}: vertices hold NaN or infinite coordinates")
    mesh = trimesh.Trimesh(vertices, faces, process=True, validate=True)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    if len(mesh.faces) == 0:
        raise BadInputError(f"{name}: every triangle is degenerate")
    diagonal = check_size(mesh.vertices, name=name, min_extent=min_extent, max_extent=max_extent)
    if not mesh.is_watertight:
        mesh.fill_holes()
    capped_edges = 0
    if not mesh.is_watertight:
        capped_edges = int((np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique)) == 1).sum())
        mesh = cap_planar_holes(mesh)
    if not mesh.is_watertight:
        edge_uses = np.bincount(mesh.edges_unique_inverse, minlength=len(mesh.edges_unique))
        open_edges, shared = int((edge_uses == 1).sum()), int((edge_uses > 2).sum())
        raise BadInputError(
            f"{name}: surface is not closed ({open_edges} open edges, "
            f"{shared} edges shared by more than 2 triangles); repair it to a watertight mesh"
        )
    bodies = mesh.split(only_watertight=False)
    if len(bodies) > 1:
        mesh = _unite(bodies, name)
    with np.errstate(divide="ignore", invalid="ignore"):  # trimesh's centre of mass divides by the volume
        volume = mesh.volume
    if not abs(volume) > tol.flat_volume * diagonal**3:  # e.g. a flat sheet, whose outline was capped
        raise BadInputError(f"{name}: encloses zero volume")
    if volume < 0:
        mesh.invert()
    if capped_edges:  # a cup modelled as one sheet is now the solid it bounds: say so
        warnings.warn(
            f"{name}: open surface closed by capping its planar holes ({capped_edges} open edges); "
            "check that it is meant to be that solid",
            RepairWarning,
            stacklevel=2,
        )
    return mesh


def cap_planar_holes(mesh, *, planarity=None):
    """Close every open boundary loop with a fan of triangles about its centroid, if all are safe to close.

    A loop is safe when it is simple (each of its vertices has one incoming and one outgoing
    open edge, consistently wound), planar (every vertex within ``planarity`` x the loop's
    largest extent of its best-fit plane) and star-shaped from its centroid (the fan winds
    once, every triangle the same way round, so no cap triangle overlaps another). The caps
    reverse the loop's open edges, so their winding agrees with the adjacent faces. Note
    that a single-sheet open shell (a cup modelled without wall thickness) becomes the
    solid it bounds.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Never modified.
    planarity : float, optional
        Default :attr:`pipeline.tol.Tolerances.cap_planarity`.

    Returns
    -------
    trimesh.Trimesh
        A new mesh with one centroid vertex and one cap per loop; ``mesh`` itself when it has
        no open edge or any loop is not safe (the caller then rejects the open surface).
    """
    planarity = tol.cap_planarity if planarity is None else planarity
    open_edges = mesh.edges[trimesh.grouping.group_rows(mesh.edges_sorted, require_count=1)]  # directed as in faces
    tails, heads = open_edges[:, 0], open_edges[:, 1]
    if len(open_edges) == 0 or len(np.unique(tails)) < len(tails) or not np.array_equal(np.sort(tails), np.sort(heads)):
        return mesh  # no loop, or a vertex on two holes, or a hole wound both ways
    successor = dict(zip(tails.tolist(), heads.tolist()))
    vertices, centres, caps = np.asarray(mesh.vertices), [], []
    while successor:
        loop = [next(iter(successor))]
        while (after := successor.pop(loop[-1])) != loop[0]:
            loop.append(after)
        points = vertices[loop]
        centre = points.mean(axis=0)
        ring = points - centre
        normal = np.linalg.svd(ring, full_matrices=False)[2][2]
        if np.abs(ring @ normal).max() > planarity * np.ptp(points, axis=0).max():
            return mesh
        ahead = np.roll(ring, -1, axis=0)
        turn = np.arctan2(np.cross(ring, ahead) @ normal, (ring * ahead).sum(axis=1))  # (len(loop),) radians
        if not (np.all(turn > 0) or np.all(turn < 0)) or abs(abs(turn.sum()) - 2 * np.pi) > 1e-6:
            return mesh
        # triangle (centre, v[i+1], v[i]) holds the open edge v[i] -> v[i+1] reversed
        centre_index = len(vertices) + len(centres)
        centres.append(centre)
        caps.append(np.column_stack([np.full(len(loop), centre_index), np.roll(loop, -1), loop]))
    return trimesh.Trimesh(np.vstack([vertices, centres]), np.vstack([mesh.faces, *caps]), process=True)


def _unite(bodies, name):
    import manifold3d

    solids = []
    for body in bodies:
        if body.volume < 0:
            body.invert()
        solid = manifold3d.Manifold(
            manifold3d.Mesh(
                vert_properties=np.asarray(body.vertices, np.float32), tri_verts=np.asarray(body.faces, np.uint32)
            )
        )
        if solid.status() != manifold3d.Error.NoError:
            raise BadInputError(f"{name}: body cannot be united ({solid.status().name})")
        solids.append(solid)
    union = manifold3d.Manifold.batch_boolean(solids, manifold3d.OpType.Add).to_mesh()
    return trimesh.Trimesh(
        np.asarray(union.vert_properties[:, :3], np.float64), np.asarray(union.tri_verts, np.int64), process=True
    )


def parse_spec(name, spec):
    """Split an ``objects`` entry of params.yaml into ``(source, scale, shape)``.

    ``spec`` is ``{source: ..., scale: 1.0, <primitive shape keywords>}``.
    """
    if not isinstance(spec, dict) or not isinstance(spec.get("source"), str):
        raise BadInputError(f"params: objects.{name} must be a mapping with a 'source' string")
    shape = {key: value for key, value in spec.items() if key not in ("source", "scale")}
    if shape and not spec["source"].startswith("primitive:"):
        raise BadInputError(f"params: objects.{name}: keys {sorted(shape)} only apply to primitive: sources")
    scale = spec.get("scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, (int, float)):
        raise BadInputError(f"params: objects.{name}.scale must be a number, got {scale!r}")
    return spec["source"], float(scale), shape


def source_key(source, shape=None):
    """Content hash of a source: the file's bytes, or the primitive's spec."""
    import hashlib
    import json

    digest = hashlib.sha256()
    if source.startswith("primitive:"):
        digest.update(json.dumps([source, shape], sort_keys=True).encode())
    else:
        path = pybullet_path(source.removeprefix("pybullet:")) if source.startswith("pybullet:") else Path(source)
        if not path.is_file():
            raise BadInputError(f"{path}: file not found")
        digest.update(path.read_bytes())
    return digest.hexdigest()[:20]

"""Artefact types: one frozen dataclass per stage output, with ``save``/``load`` beside it.

Every artefact is a single ``.npz`` written atomically (temp file in the same folder,
then ``os.replace``), loadable without pickle. Keys, all in metres and radians, object frame:

``SurfaceSamples`` (``surface.npz``, stage ``sample``)
    points (n, 3) float64; normals (n, 3) float64, unit, outward; face_index (n,) int64,
    the triangle each sample lies on (-1 for point clouds); vertices (v, 3) float64 and
    faces (f, 3) int64 of the validated, scaled mesh (empty for clouds); spacing, the
    median distance between neighbouring samples; source, the object's origin.
``MedialAxis`` (``medial_axis.npz``, stage ``medial_axis``)
    centers (m, 3) float64; radii (m,) float64, the method's ball radii; sample_index (m,)
    int64, the surface sample the ball was grown from; contacts (m, c) int64, samples the
    method found on the ball (shrinking ball: p and q; Voronoi poles: the 4 tetrahedron
    vertices), -1 padded; method.
``MedialSpheres`` (``spheres.npz``, stage ``mat``)
    centers (s, 3) float64; radii (s,) float64, distance to the nearest sample; contacts
    (s, k) int64, touching samples (within r (1 + tau)), nearest first, -1 padded;
    object_angle (s,) float64, radians in [0, pi].
``SphereGrid`` (``sphere_grid.npz``, stage ``sphere_grid``)
    the sphere arrays above plus the cell grid of eq. 1 over the centres: origin (3,),
    cell_size, dims (3,) int64, order (s,) int64 (sphere ids sorted by cell), cell_start
    (cells + 1,) int64.

``Symmetry`` (``symmetry.npz``, stage ``classify``)
    see :class:`pipeline.geometry.symmetry.Symmetry`.
``candidates.parquet`` (stage ``candidates``)
    one row per candidate grasp and hand; columns in :data:`pipeline.geometry.candidates.COLUMNS`.

Every file also holds ``schema`` (:data:`SCHEMA_VERSION`), ``kind`` and ``key``: a content
hash of the stage's inputs and params, so a batch runner can tell a result is reusable.
"""

import contextlib
import dataclasses
import hashlib
import json
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .errors import ArtefactError

SCHEMA_VERSION = 1
_UMASK = os.umask(0o022)
os.umask(_UMASK)  # read once: os.umask can only be read by setting it


def content_key(stage, params, *parents):
    """Stable hex key of a stage run: stage name, params (a dataclass or mapping), parent keys."""
    if dataclasses.is_dataclass(params):
        params = dataclasses.asdict(params)
    blob = json.dumps([stage, params, list(parents)], sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:20]


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temp path beside ``path``; rename it to ``path`` when the block succeeds.

    A crash or error leaves no file under ``path`` (nor the temp file).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp's 0600 would make shared results unreadable to others
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        Path(tmp).unlink(missing_ok=True)


def json_ready(value):
    """``value`` with NaN and infinities as None, numpy values as Python ones: JSON has no such
    numbers (Foxglove's parser refuses them). An empty result's rate is NaN in memory and in
    tables, null in JSON."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_ready(item) for item in value]
    if isinstance(value, (np.ndarray, np.generic)):
        return json_ready(value.tolist())
    return value


def json_bytes(value, *, indent=None):
    """``value`` as strict JSON (:func:`json_ready`), UTF-8."""
    return json.dumps(json_ready(value), indent=indent, allow_nan=False).encode()


def atomic_write(path, write):
    """Call ``write(file_object)`` on a temp file beside ``path``, then rename it into place
    (see :func:`atomic_path`)."""
    with atomic_path(path) as tmp, open(tmp, "wb") as stream:
        write(stream)


def write_table(path, table):
    """Write a pandas DataFrame as parquet, atomically."""
    atomic_write(path, lambda stream: table.to_parquet(stream, index=False))


def read_table(path):
    """Read a parquet table written by :func:`write_table`; ArtefactError if unreadable."""
    import pandas as pd

    try:
        return pd.read_parquet(path)
    except FileNotFoundError:
        raise ArtefactError(f"{path}: missing (run the stage that makes it first)") from None
    except Exception as err:  # noqa: BLE001 - pyarrow raises many types for a bad file
        raise ArtefactError(f"{path}: not a readable parquet table ({type(err).__name__})") from None


class _Artefact:
    """Save/load for frozen dataclasses whose fields are arrays, strings or floats."""

    KIND = ""
    ARRAYS = {}  # field -> (dtype, columns): columns None for 1-D, 0 for any width

    def __post_init__(self):
        for name, (dtype, columns) in self.ARRAYS.items():
            value = np.asarray(getattr(self, name), dtype=dtype)
            shape_ok = (
                value.ndim == 1
                if columns is None
                else (value.ndim == 2 and (columns == 0 or value.shape[1] == columns))
            )
            if not shape_ok:
                wanted = "(n,)" if columns is None else f"(n, {columns or 'k'})"
                raise ArtefactError(f"{self.KIND}.{name}: expected shape {wanted}, got {value.shape}")
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def save(self, path):
        """Write atomically to ``path`` (.npz)."""
        arrays, meta = {}, {"schema": SCHEMA_VERSION, "kind": self.KIND}
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if item.name in self.ARRAYS:
                arrays[item.name] = value
            else:
                meta[item.name] = value
        arrays["meta"] = np.array(json.dumps(meta))
        atomic_write(path, lambda stream: np.savez(stream, **arrays))

    @classmethod
    def load(cls, path):
        """Read an artefact written by :meth:`save`; raises ArtefactError on a bad file."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as data:
                contents = {name: data[name] for name in data.files}
        except FileNotFoundError:
            raise ArtefactError(f"{path}: missing (run the stage that makes it first)") from None
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
            raise ArtefactError(f"{path}: not a readable .npz artefact ({err})") from None
        try:
            meta = json.loads(str(contents.pop("meta")))
        except (KeyError, json.JSONDecodeError):
            raise ArtefactError(f"{path}: no metadata; not written by this pipeline") from None
        if meta.pop("kind", None) != cls.KIND:
            raise ArtefactError(f"{path}: is not a {cls.KIND} artefact")
        if meta.pop("schema", None) != SCHEMA_VERSION:
            raise ArtefactError(f"{path}: schema version differs from {SCHEMA_VERSION}; rerun its stage")
        names = {f.name for f in dataclasses.fields(cls)}
        if set(contents) | set(meta) != names:
            raise ArtefactError(f"{path}: fields {sorted(set(contents) | set(meta))} do not match {cls.KIND}")
        return cls(**contents, **meta)


@dataclass(frozen=True)
class SurfaceSamples(_Artefact):
    """Oriented surface samples of one object, plus the mesh they came from."""

    points: np.ndarray
    normals: np.ndarray
    face_index: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    spacing: float
    source: str
    key: str

    KIND = "surface_samples"
    ARRAYS = {
        "points": (np.float64, 3),
        "normals": (np.float64, 3),
        "face_index": (np.int64, None),
        "vertices": (np.float64, 3),
        "faces": (np.int64, 3),
    }


@dataclass(frozen=True)
class MedialAxis(_Artefact):
    """Medial axis point cloud with each ball's radius and its defining samples."""

    centers: np.ndarray
    radii: np.ndarray
    sample_index: np.ndarray
    contacts: np.ndarray
    method: str
    key: str

    KIND = "medial_axis"
    ARRAYS = {
        "centers": (np.float64, 3),
        "radii": (np.float64, None),
        "sample_index": (np.int64, None),
        "contacts": (np.int64, 0),
    }


@dataclass(frozen=True)
class MedialSpheres(_Artefact):
    """The medial spheres of paper II-B: centre, radius, touching samples, object angle."""

    centers: np.ndarray
    radii: np.ndarray
    contacts: np.ndarray
    object_angle: np.ndarray
    key: str

    KIND = "medial_spheres"
    ARRAYS = {
        "centers": (np.float64, 3),
        "radii": (np.float64, None),
        "contacts": (np.int64, 0),
        "object_angle": (np.float64, None),
    }

    def __len__(self):
        return len(self.radii)


@dataclass(frozen=True)
class SphereGrid(_Artefact):
    """Medial spheres sorted into the cubic cell grid of eq. 1 (see :mod:`pipeline.geometry.sphere_grid`)."""

    centers: np.ndarray
    radii: np.ndarray
    object_angle: np.ndarray
    origin: np.ndarray
    dims: np.ndarray
    order: np.ndarray
    cell_start: np.ndarray
    cell_size: float
    key: str

    KIND = "sphere_grid"
    ARRAYS = {
        "centers": (np.float64, 3),
        "radii": (np.float64, None),
        "object_angle": (np.float64, None),
        "origin": (np.float64, None),
        "dims": (np.int64, None),
        "order": (np.int64, None),
        "cell_start": (np.int64, None),
    }

    def __len__(self):
        return len(self.radii)

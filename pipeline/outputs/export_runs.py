"""The runs of an export: every object x scale x hand with trials in a `plan --out` folder, a
`batch` output, the DVC data/ tree or the report/ folder (:func:`find_runs`), and the simulated
mesh of each (:func:`load_mesh`)."""

import functools
import json
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ArtefactError, BadInputError


@dataclass(frozen=True)
class Run:
    """The trials of one object, scale and hand as found on disk.

    ``trials`` holds the hand's rows with the checks' columns (missing where unchecked) and
    ``trial``, the row in the file ``origin``; ``mesh`` says where the simulated mesh is:
    ``("surface", path)`` a surface.npz, ``("source", source, scale)`` a mesh the sample stage
    rebuilds."""

    object: str
    scale: float
    hand: str
    trials: pd.DataFrame
    mesh: tuple
    origin: str


def find_runs(run_dir, *, data=None, scale=1.0, warn=None):
    """Every object x scale x hand with trials under ``run_dir``.

    Parameters
    ----------
    run_dir : path
        One of: a ``plan --out`` folder (trials.parquet beside surface.npz and summary.json), a
        ``batch`` output (objects/ and trials/), a DVC ``data/`` tree (or any folder above or in
        one: ``<object>/<scale>/surface.npz`` and ``<object>/<scale>/<hand>/trials.parquet``, each
        with its checks.parquet if there), the ``report/`` folder (trials.parquet with ``object``
        and ``scale`` columns), or a folder holding several plan folders.
    data : path, optional
        The DVC data/ tree holding a report's meshes (default: ``run_dir/../data``).
    scale : float
        A batch's ``--scale`` (its output does not record it); checked against its trials.
    warn : callable(str), optional
        Called with a line for each batch trials file left out (its object not done).

    Returns
    -------
    list of Run, sorted by object, scale and hand
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise BadInputError(f"{run_dir}: no such folder")
    table = run_dir / "trials.parquet"
    if table.is_file() and (run_dir / "surface.npz").is_file():
        runs = _plan_runs(run_dir)
    elif table.is_file() and {"object", "scale"} <= set(_columns(table)):
        runs = _report_runs(run_dir, Path(data) if data else run_dir.parent / "data")
    elif (run_dir / "objects").is_dir() and (run_dir / "trials").is_dir():
        runs = _batch_runs(run_dir, scale, warn or (lambda line: None))
    else:
        runs = []
        for found in _trial_files(run_dir):
            if (found.parent / "surface.npz").is_file():
                runs += _plan_runs(found.parent)
            elif (found.parent.parent / "surface.npz").is_file():
                runs += _dvc_runs(found)
    runs = [run for run in runs if len(run.trials)]
    if not runs:
        raise BadInputError(
            f"{run_dir}: holds no trials (give a `plan --out` folder, a `batch` output, the DVC data/ tree "
            "or the report/ folder)"
        )
    return sorted(runs, key=lambda run: (run.object, run.scale, run.hand))


def _columns(path):
    import pyarrow.parquet

    try:
        return pyarrow.parquet.read_schema(path).names
    except Exception as err:  # noqa: BLE001 - pyarrow raises many types for a bad file
        raise ArtefactError(f"{path}: not a readable parquet table ({type(err).__name__})") from None


def _trial_files(folder):
    """trials.parquet files under ``folder``, hidden folders (.venv, .dvc, .git) skipped."""
    for root, folders, files in os.walk(folder):
        folders[:] = sorted(name for name in folders if not name.startswith("."))
        if "trials.parquet" in files:
            yield Path(root) / "trials.parquet"


def _numbered(trials):
    return trials.reset_index(drop=True).assign(trial=np.arange(len(trials), dtype=np.int64))


def _with_checks(trials, checks_path):
    from ..artefacts import read_table
    from ..checks.protocol import with_checks

    try:
        return with_checks(trials, read_table(checks_path) if checks_path.is_file() else None)
    except ArtefactError as err:
        raise ArtefactError(f"{checks_path}: {err}") from None


def _by_hand(trials, *, object, scale, mesh, origin):
    return [
        Run(object, float(scale), str(hand), rows, mesh, origin)
        for hand, rows in trials.groupby(trials.hand.astype(str), sort=True)
    ]


def _plan_runs(folder):
    from ..artefacts import read_table

    summary = folder / "summary.json"
    if not summary.is_file():
        raise ArtefactError(f"{summary}: missing (a plan folder names its object and scale there)")
    meta = json.loads(summary.read_text())
    if not {"source", "scale"} <= set(meta):
        raise ArtefactError(f"{summary}: no source or scale (not written by `plan`?)")
    trials = _numbered(read_table(folder / "trials.parquet"))
    if not len(trials):
        return []
    trials = _with_checks(trials, folder / "checks.parquet")
    name = Path(str(meta["source"]).split(":")[-1]).stem or folder.name
    return _by_hand(
        trials, object=name, scale=meta["scale"], mesh=("surface", str(folder / "surface.npz")), origin=str(folder)
    )


def _dvc_runs(path):
    from ..artefacts import read_table

    run = path.parent.parent
    try:
        scale = float(run.name)
    except ValueError:
        raise BadInputError(f"{run}: a DVC run folder is data/<object>/<scale>; {run.name!r} is no scale") from None
    trials = _numbered(read_table(path))
    if not len(trials):
        return []
    trials = _with_checks(trials, path.with_name("checks.parquet"))
    return _by_hand(
        trials, object=run.parent.name, scale=scale, mesh=("surface", str(run / "surface.npz")), origin=str(path)
    )


def _report_runs(folder, data):
    from ..artefacts import read_table

    trials = _numbered(read_table(folder / "trials.parquet"))
    runs = []
    for (name, scale), rows in trials.groupby([trials.object.astype(str), trials.scale.astype(float)], sort=True):
        surface = _scale_folder(data / name, scale) / "surface.npz"
        if not surface.is_file():
            raise BadInputError(
                f"{folder / 'trials.parquet'}: no mesh for {name} x{scale:g}: {surface} is missing "
                "(give the DVC data/ tree with --data)"
            )
        runs += _by_hand(rows, object=name, scale=scale, mesh=("surface", str(surface)), origin=str(folder))
    return runs


def _scale_folder(folder, scale):
    """``folder/<scale>``: the folder whose name is the number ``scale`` (``1.0`` or ``1``)."""
    if folder.is_dir():
        for child in sorted(folder.iterdir()):
            try:
                if float(child.name) == scale:
                    return child
            except ValueError:
                continue
    return folder / str(float(scale))


def _batch_runs(folder, scale, warn):
    from ..artefacts import read_table

    sources = {}
    if any((folder / "objects").glob("*.parquet")):
        objects = pd.read_parquet(folder / "objects", columns=["object", "status", "source"])
        objects = objects[objects.status == "ok"]  # a summary row marks an object done
        sources = dict(zip(objects.object, objects.source))
    runs = []
    for path in sorted((folder / "trials").glob("*.parquet")):
        trials = _numbered(read_table(path))
        if not len(trials):
            continue
        name = str(trials.object.iloc[0])
        if name not in sources:  # written before the batch stopped: it plans the object again
            warn(f"{path}: left out, object {name!r} is not done in {folder / 'objects'}")
            continue
        mesh = ("source", str(sources[name]), float(scale))
        _check_batch_scale(trials, mesh, path)
        runs += _by_hand(trials, object=name, scale=scale, mesh=mesh, origin=str(path))
    return runs


def _check_batch_scale(trials, mesh, path):
    """The baseline trials' grasp points are surface samples: they lie on the mesh at the batch's scale."""
    from ..arrays import vectors
    from ..geometry.mesh_query import ObjectMesh

    baseline = trials[trials.planner.astype(str) == "baseline"]
    if not len(baseline):
        return
    vertices, faces = load_mesh(mesh)
    gap = ObjectMesh(vertices, faces, grid_cells=8).distance(vectors(baseline, "grasp")).max()
    size = np.linalg.norm(np.ptp(vertices, axis=0))
    if not gap <= 1e-6 * max(size, 1.0):
        raise BadInputError(
            f"{path}: its trials are not on {mesh[1]} at scale {mesh[2]:g} (off by {gap:.3g} m): "
            "give the batch's --scale"
        )


@functools.lru_cache(maxsize=8)
def load_mesh(mesh):
    """(vertices (v, 3) float64 metres, faces (f, 3) int64) of a :class:`Run`'s ``mesh``."""
    if mesh[0] == "surface":
        from ..artefacts import SurfaceSamples

        surface = SurfaceSamples.load(mesh[1])
        return surface.vertices, surface.faces
    from ..geometry.objects import load_source, validate_mesh

    with warnings.catch_warnings():  # the batch warned of its repairs when it ran
        warnings.simplefilter("ignore")
        kind, *loaded = load_source(mesh[1], scale=mesh[2])
        if kind != "mesh":
            raise BadInputError(f"{mesh[1]}: a point cloud has no grasps to export")
        solid = validate_mesh(loaded[0], name=mesh[1], min_extent=0.0, max_extent=np.inf)
    vertices, faces = np.asarray(solid.vertices, np.float64), np.asarray(solid.faces, np.int64)
    vertices.setflags(write=False)  # cached: shared by every caller
    faces.setflags(write=False)
    return vertices, faces

"""A folder of meshes as ``objects`` entries of params.yaml (``python -m pipeline objects DIR``).

DVC expands its stages from params.yaml when it reads dvc.yaml, before any stage runs, so a
folder cannot be listed at run time: this module writes one entry per mesh instead.
"""

import dataclasses
import json
import re
import warnings

import numpy as np
import yaml

from ..errors import BadInputError, PipelineError
from ..params import Params, ReportParams, SampleParams, parse_scales, read_mapping, section_from_mapping
from .objects import RepairWarning, check_size, load_source, mesh_files, object_name, select_meshes
from .sampling import sample_object


def folder_entries(folder, *, prefix="", scale=None, size=None, only=None, params_path=None, warn=None):
    """``{name: {"source": path, "scale": s}}`` for every mesh file under ``folder`` (recursively,
    natural order) that passes the ``sample`` stage's own load, repairs and checks at every
    params scale; a file that fails is skipped with ``warn(message)`` naming it.

    Parameters
    ----------
    folder : str or Path
        Or ``pybullet:DIR``.
    prefix : str
        Put before each name (:func:`pipeline.geometry.objects.object_name`).
    scale : float, optional
        The same factor for every mesh (0.001 for millimetres).
    size : float, optional
        Instead of ``scale``: metres of each mesh's bounding-box diagonal (for unitless meshes,
        such as the segmentation benchmark's); the scale is computed per file.
    only : iterable of str, optional
        File stems to keep (e.g. the benchmark ids of Table I: ``1``, ``41``, ...).
    params_path : str or Path, optional
        The params file whose ``sample`` section and ``scales`` the checks use (None: defaults).
    warn : callable(str), optional
        Receives the skipped files and the repairs (capped holes).
    """
    warn = warn or (lambda message: None)
    if scale is not None and size is not None:
        raise BadInputError("give --scale or --size, not both")
    root, files = mesh_files(folder)
    named = select_meshes([(object_name(relative, prefix), path) for relative, path in files], folder=root, only=only)
    first = {}
    for name, path in named:
        if name in first:  # two files would share data/<name>/ and their DVC stages
            raise BadInputError(f"{first[name]} and {path} both give the object name {name!r}; rename one")
        first[name] = path
    sample, scales = _sample_checks(params_path)
    entries = {}
    for name, path in named:
        try:
            entries[name] = {"source": str(path), "scale": _checked_scale(path, scale, size, sample, scales, warn)}
        except PipelineError as err:  # one bad file in a folder should not stop the listing
            warn(f"skipped {err}")
    if not entries:
        raise BadInputError(f"{root}: no mesh passed the sample stage's checks (see the warnings above)")
    return entries


def replace_objects(params_text, entries):
    """params.yaml's text with its top-level ``objects:`` block replaced by ``entries``; comments
    and every other section are kept as written."""
    lines = params_text.splitlines(keepends=True)
    starts = [number for number, line in enumerate(lines) if line.startswith("objects:")]
    if not starts:
        raise BadInputError("params.yaml: no top-level 'objects:' section to replace")
    end = starts[0] + 1
    # the block runs over indented and blank lines; a comment in column 0 after a blank line
    # belongs to the next section
    while end < len(lines) and (
        lines[end].startswith((" ", "\t"))
        or not lines[end].strip()
        or (lines[end].startswith("#") and lines[end - 1].strip())
    ):
        end += 1
    while end > starts[0] + 1 and not lines[end - 1].strip():
        end -= 1  # keep the blank lines before the next section
    block = ["objects:\n"] + [f"  {line}\n" for line in entry_lines(entries)]
    text = "".join(lines[: starts[0]] + block + lines[end:])
    if yaml.safe_load(text)["objects"] != entries:  # a path YAML would misread: refuse, change nothing
        raise BadInputError("params.yaml: the new objects section does not read back as written")
    return text


def entry_lines(entries):
    """One flow-style YAML line per entry: ``name: {source: "...", scale: s}``."""
    return [
        f"{name}: {{source: {json.dumps(spec['source'])}, scale: {spec['scale']}}}" for name, spec in entries.items()
    ]


def _sample_checks(path):
    """``(SampleParams, scales)`` of the params file at ``path`` (None: the defaults): what the sample
    stage checks a mesh with. Only these are read, so a file whose other sections no longer fit its
    objects (figure_objects of an earlier listing) can still be rewritten."""
    if path is None:
        return Params().sample, list(Params().scales)
    raw = read_mapping(path)
    sample = section_from_mapping(SampleParams, raw.get("sample"), section="sample", source=str(path))
    return sample, [float(scale) for scale in parse_scales(raw.get("scales", [1.0]), source=path)]


def _checked_scale(path, scale, size, sample, scales, warn):
    """The object scale of the mesh at ``path`` (``scale``, or the one giving a ``size`` m diagonal),
    after the sample stage's checks at each of ``scales``; raises BadInputError naming the file."""
    factor = 1.0 if scale is None else float(scale)
    if size is not None:
        loaded = load_source(str(path))
        points = np.asarray(loaded[1].vertices if loaded[0] == "mesh" else loaded[1])
        if not (len(points) and np.isfinite(points).all()):
            raise BadInputError(f"{path}: no points, or NaN or infinite coordinates")
        diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
        if not diagonal > 0:
            raise BadInputError(f"{path}: all points coincide, no size to scale to --size {size:g}")
        factor = float(size) / diagonal
    factor = float(f"{factor:.6g}")  # as written into params.yaml
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RepairWarning)
        # the stage's own load, repairs and checks; few samples, since only the checks matter here
        surface = sample_object(
            str(path),
            scale=factor * scales[0],
            rng=np.random.default_rng(0),
            **{**dataclasses.asdict(sample), "count": 100},
        )
    for repair in caught:
        warn(str(repair.message))
    coordinates = surface.vertices if len(surface.vertices) else surface.points
    for other in scales[1:]:  # the stage runs the object at every params scale: the units check at each
        try:
            check_size(
                coordinates * (other / scales[0]),
                name=str(path),
                min_extent=sample.min_extent_m,
                max_extent=sample.max_extent_m,
            )
        except BadInputError as err:
            raise BadInputError(f"{err} [at params scale {other:g}]") from None
    return factor


def figure_objects_following(text, names, *, source):
    """``text`` (a params file) with ``report.figure_objects`` kept to the objects ``names``: the ones
    it names that remain, else the first up to 3 of ``names``. Returns ``(text, figure_objects)``."""
    report = (yaml.safe_load(text) or {}).get("report") or {}
    before = report.get("figure_objects", ReportParams().figure_objects) if isinstance(report, dict) else []
    figures = [name for name in before if name in names] or names[:3]
    if figures == before and "figure_objects" in report:
        return text, figures
    flow = "[" + ", ".join(name if yaml.safe_load(name) == name else json.dumps(name) for name in figures) + "]"
    lines = text.splitlines(keepends=True)
    section = next((number for number, line in enumerate(lines) if re.match(r"report:\s*(#.*)?$", line)), None)
    if section is None:
        text = text + ("" if text.endswith("\n") or not text else "\n") + f"\nreport:\n  figure_objects: {flow}\n"
    else:
        end = section + 1
        while end < len(lines) and (lines[end].startswith((" ", "\t")) or not lines[end].strip()):
            end += 1
        key = next(
            (number for number in range(section + 1, end) if re.match(r"\s+figure_objects:", lines[number])), None
        )
        if key is None:
            lines.insert(section + 1, f"  figure_objects: {flow}\n")
        else:
            indent, rest = re.match(r"(\s+figure_objects:)(.*)", lines[key].rstrip("\n")).groups()
            comment = re.search(r"\s+#.*$", rest[rest.find("]") + 1 :] if "[" in rest else rest)
            lines[key] = f"{indent} {flow}{comment.group(0) if comment else ''}\n"
            if "[" not in rest:  # a block list: drop its "- name" lines
                after = key + 1
                while after < end and re.match(r"\s+-\s", lines[after]):
                    del lines[after]
                    end -= 1
        text = "".join(lines)
    try:
        written = (yaml.safe_load(text).get("report") or {}).get("figure_objects")
    except yaml.YAMLError:  # e.g. a flow list over several lines, only partly replaced
        written = None
    if written != figures:
        raise BadInputError(f"{source}: report.figure_objects cannot be rewritten to {figures} (edit it by hand)")
    return text, figures

"""A folder of meshes as ``objects`` entries of params.yaml (``python -m pipeline objects DIR``).

DVC expands its stages from params.yaml when it reads dvc.yaml, before any stage runs, so a
folder cannot be listed at run time: this module writes one entry per mesh instead.
"""

import json
import re
from pathlib import Path

import numpy as np
import yaml

from .errors import BadInputError
from .objects import MESH_SUFFIXES, load_source


def natural_key(path):
    """Sort key of a path by its stem, numbers by value (``2`` before ``10``)."""
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", path.stem)]


def folder_entries(folder, *, prefix="", scale=None, size=None, only=None):
    """``{name: {"source": path, "scale": s}}`` for every mesh file in ``folder`` (natural order).

    Parameters
    ----------
    folder : str or Path
    prefix : str
        Put before each file's stem to make the object name (names keep ``[A-Za-z0-9_]``; one
        not starting with a letter gets ``mesh_`` in front).
    scale : float, optional
        The same factor for every mesh (0.001 for millimetres).
    size : float, optional
        Instead of ``scale``: metres of each mesh's bounding-box diagonal (for unitless meshes,
        such as the segmentation benchmark's); the scale is computed per file.
    only : iterable of str, optional
        File stems to keep (e.g. the benchmark ids of Table I: ``1``, ``41``, ...).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise BadInputError(f"{folder}: not a folder")
    if scale is not None and size is not None:
        raise BadInputError("give --scale or --size, not both")
    paths = sorted((path for path in folder.iterdir() if path.suffix.lower() in MESH_SUFFIXES), key=natural_key)
    if only is not None:
        wanted = {str(stem) for stem in only}
        missing = sorted(wanted - {path.stem for path in paths})
        if missing:
            raise BadInputError(f"{folder}: no mesh named {', '.join(missing)}")
        paths = [path for path in paths if path.stem in wanted]
    if not paths:
        raise BadInputError(f"{folder}: holds no mesh ({', '.join(sorted(MESH_SUFFIXES))})")
    entries = {}
    for path in paths:
        factor = 1.0 if scale is None else float(scale)
        if size is not None:
            loaded = load_source(str(path.resolve()))
            points = loaded[1].vertices if loaded[0] == "mesh" else loaded[1]
            factor = float(size) / float(np.linalg.norm(np.ptp(np.asarray(points), axis=0)))
        name = re.sub(r"\W", "_", f"{prefix}{path.stem}")
        name = name if name[:1].isalpha() else f"mesh_{name}"  # YAML would read a key 1 as a number
        entries[name] = {"source": str(path.resolve()), "scale": float(f"{factor:.6g}")}
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
    while end < len(lines) and (lines[end].startswith((" ", "\t")) or not lines[end].strip()
                                or (lines[end].startswith("#") and lines[end - 1].strip())):
        end += 1
    while end > starts[0] + 1 and not lines[end - 1].strip():
        end -= 1  # keep the blank lines before the next section
    block = ["objects:\n"] + [f"  {line}\n" for line in entry_lines(entries)]
    text = "".join(lines[:starts[0]] + block + lines[end:])
    if yaml.safe_load(text)["objects"] != entries:  # a path YAML would misread: refuse, change nothing
        raise BadInputError("params.yaml: the new objects section does not read back as written")
    return text


def entry_lines(entries):
    """One flow-style YAML line per entry: ``name: {source: "...", scale: s}``."""
    return [f"{name}: {{source: {json.dumps(spec['source'])}, scale: {spec['scale']}}}" for name, spec in entries.items()]

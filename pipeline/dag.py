"""The DAG's stages in one table, and the DVC stage files written from it.

Each :class:`Stage` names its artefacts, the params DVC tracks for it and its module in
``stages/``; its code deps are that module's ``pipeline`` imports, followed transitively (every
``import`` statement, function-level ones included), so that editing any module a stage can run
reruns the stage. ``python -m pipeline.dag`` rewrites the stage files from this table and the
objects of ``params.yaml``; ``python -m pipeline.dag --check`` only lists the files that differ
(or should not be there), and fails if any does.

The files: ``dag/<stage>/dvc.yaml`` holds the stage's ``code`` stage, whose output
``dag/<stage>/code.json`` (the md5 of each source file) is the runs' one code dep, and
``dag/<stage>/<object>/dvc.yaml`` the object's runs (a matrix over scales, and hands; one run
of the first scale for a stage that is not :attr:`Stage.per_scale`). DVC
rewrites a file's whole dvc.lock after every stage it runs (a ruamel round trip: 1.7 s for the
56 entries of one file per stage), so each lock holds only one object's two to four entries.
"""

import ast
import functools
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

from .errors import PipelineError

ROOT = Path(__file__).resolve().parents[1]

#: file of each artefact; those of :data:`PER_HAND` lie in the run's ``<hand>/`` folder
ARTEFACTS = {
    "surface": "surface.npz",
    "medial_axis": "medial_axis.npz",
    "spheres": "spheres.npz",
    "sphere_grid": "sphere_grid.npz",
    "symmetry": "symmetry.npz",
    "concavities": "concavity.npz",
    "candidates": "candidates.parquet",
    "trials": "trials.parquet",
    "contacts": "contacts.parquet",
    "parts": "parts.npz",
    "checks": "checks.parquet",
}
PER_HAND = ("candidates", "trials", "contacts", "checks")
#: artefacts of the object, not of a run (in ``data/<object>/``): what an object has at every scale
PER_OBJECT = ("parts",)


@dataclass(frozen=True)
class Stage:
    """One DAG stage: ``python -m stages.<name> INPUTS... ARGS... OUTPUTS...``, run per object and
    scale (and hand when ``per_hand``; once per object, on the first of ``scales``, when not
    ``per_scale``: its outputs, of :data:`PER_OBJECT`, serve every scale); ``args`` are matrix
    items (``object``, ``scale``, ``hand``); ``params`` the params.yaml keys DVC tracks;
    ``recording`` the .rrd it writes and ``recorded`` the artefacts it reads only to draw it
    (after the inputs on the command line).

    ``function`` (``module:name``) computes the outputs from the inputs, in order, and the
    keywords of the params ``section`` (every key of it; empty: the caller passes the ones it
    needs, with the hands, seed and workers); the stage module and :func:`pipeline.plan.run_chain`
    both call it (a test checks the stage modules)."""

    name: str
    inputs: tuple
    outputs: tuple
    params: tuple
    function: str = ""
    section: str = ""
    args: tuple = ()
    per_hand: bool = False
    per_scale: bool = True
    recording: str = ""
    recorded: tuple = ()


STAGES = (
    Stage(
        "sample",
        (),
        ("surface",),
        ("seed", "sample", "objects.${item.object}"),
        "pipeline.geometry.sampling:sample_object",
        "sample",
        args=("object", "scale"),
    ),
    Stage(
        "medial_axis",
        ("surface",),
        ("medial_axis",),
        ("medial_axis",),
        "pipeline.geometry.medial_axis:medial_axis",
        "medial_axis",
    ),
    Stage("mat", ("surface", "medial_axis"), ("spheres",), ("mat",), "pipeline.geometry.mat:reconstruct", "mat"),
    Stage(
        "sphere_grid",
        ("spheres",),
        ("sphere_grid",),
        ("sphere_grid",),
        "pipeline.geometry.sphere_grid:build",
        "sphere_grid",
    ),
    Stage(
        "classify",
        ("sphere_grid",),
        ("symmetry",),
        ("record", "classify"),
        "pipeline.geometry.symmetry:classify",
        "classify",
        recording="object.rrd",
        recorded=("surface",),
    ),
    Stage(
        "concavity",
        ("surface",),
        ("concavities",),
        ("seed", "record", "sample", "medial_axis", "mat", "sphere_grid", "classify", "concavity"),
        "pipeline.geometry.concavity:encompass",
        "concavity",
        recording="concavity.rrd",
    ),
    Stage(
        "candidates",
        ("symmetry", "concavities"),
        ("candidates",),
        (
            "candidates.approach_directions",
            "candidates.flipped_candidates",
            "candidates.centre_rims",
            "concavity.max_width_ratio",
        ),
        "pipeline.geometry.candidates:generate_for_hands",
        args=("hand",),
        per_hand=True,
    ),
    Stage(
        "simulate",
        ("surface", "candidates"),
        ("trials", "contacts"),
        ("record", "seed", "simulate"),
        "pipeline.trial.protocol:simulate",
        args=("hand",),
        per_hand=True,
        recording="grasps.rrd",
    ),
    Stage(
        "decompose",
        ("surface",),
        ("parts",),
        ("checks.vhacd_resolution", "checks.physics"),
        "pipeline.checks.physics:decompose",
        args=("scale",),
        per_scale=False,
    ),
    Stage(
        "check",
        ("surface", "trials", "parts"),
        ("checks",),
        ("seed", "simulate", "checks"),
        "pipeline.checks.protocol:check_trials",
        "checks",
        args=("scale", "hand"),
        per_hand=True,
    ),
)
#: the report reads every run's artefacts under ``data/`` (it is not per run)
REPORT = Stage(
    "report",
    (),
    (),
    (
        "seed",
        "objects",
        "scales",
        "candidates.hands",
        "simulate.spheres_per_object",
        "simulate.mu",
        "simulate.cone_edges",
        "report",
    ),
)


def stage(name):
    """The :class:`Stage` named ``name``."""
    for entry in STAGES + (REPORT,):
        if entry.name == name:
            return entry
    raise PipelineError(f"no stage named {name!r} (stages: {', '.join(s.name for s in STAGES + (REPORT,))})")


def function(entry):
    """The callable :attr:`Stage.function` names (imported on use, so that the table itself
    imports none of the stages' code)."""
    import importlib

    module, name = entry.function.split(":")
    return getattr(importlib.import_module(module), name)


def _module_file(parts):
    """The source file of module ``pipeline.<parts>`` (a package's ``__init__.py``), or None."""
    base = ROOT.joinpath("pipeline", *parts)
    for path in (base / "__init__.py", base.with_suffix(".py")):
        if parts and path.is_file():
            return path
    return None


def module_path(name):
    """Repository-relative source file of the module ``name`` (``pipeline.trial.engine``; a
    package's ``__init__.py``)."""
    return str(_module_file(name.split(".")[1:]).relative_to(ROOT)) if "." in name else "pipeline/__init__.py"


def _imported(path):
    """``pipeline`` modules (tuples of names below ``pipeline``) that the source file ``path``
    imports anywhere in it; ``from package import module`` counts the module too."""
    path = Path(path).resolve()
    tree = ast.parse(path.read_text(), filename=str(path))
    inside = (ROOT / "pipeline") in path.parents
    package = list(path.relative_to(ROOT / "pipeline").parent.parts) if inside else None
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(tuple(a.name.split(".")[1:]) for a in node.names if a.name.startswith("pipeline."))
            continue
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level and inside:
            base = package[: len(package) - (node.level - 1)]
        elif node.level == 0 and (node.module or "").split(".")[0] == "pipeline":
            base = []
        else:
            continue
        module = base + [part for part in (node.module or "").split(".") if part and part != "pipeline"]
        if module:
            found.add(tuple(module))
        found.update(tuple(module + [alias.name]) for alias in node.names if _module_file(module + [alias.name]))
    return {parts for parts in found if _module_file(list(parts))}


@functools.cache
def code_deps(name):
    """Repository-relative source files stage ``name`` can run: ``stages/<name>.py``, the
    ``pipeline`` package's ``__init__.py`` and every ``pipeline`` module it imports, transitively,
    with the ``__init__.py`` of each sub-package on the way (Python runs them)."""
    seen, todo = set(), sorted(_imported(ROOT / "stages" / f"{name}.py"))
    while todo:
        module = todo.pop()
        if module not in seen:
            seen.add(module)
            todo += sorted(_imported(_module_file(list(module))) - seen)
            todo += [module[:depth] for depth in range(1, len(module)) if module[:depth] not in seen]
    files = {str(_module_file(list(module)).relative_to(ROOT)) for module in seen}
    return (f"stages/{name}.py", "pipeline/__init__.py") + tuple(sorted(files))


def fingerprint_path(name):
    """Repository-relative path of stage ``name``'s code fingerprint."""
    return f"dag/{name}/code.json"


def fingerprint(name, root=ROOT):
    """``{"stage": name, "files": {path: md5}}`` of the stage's code deps (bytes as on disk)."""
    files = {path: hashlib.md5((Path(root) / path).read_bytes()).hexdigest() for path in code_deps(name)}
    return {"stage": name, "files": files}


def write_fingerprint(name, path):
    """Write :func:`fingerprint` of stage ``name`` to ``path`` as JSON, atomically."""
    from .artefacts import atomic_write

    text = json.dumps(fingerprint(name), indent=1, sort_keys=True) + "\n"
    atomic_write(path, lambda stream: stream.write(text.encode()))


def _path(artefact, name, scale="${item.scale}"):
    if artefact in PER_OBJECT:
        return f"data/{name}/{ARTEFACTS[artefact]}"
    run = f"data/{name}/{scale}"
    return f"{run}/${{item.hand}}/{ARTEFACTS[artefact]}" if artefact in PER_HAND else f"{run}/{ARTEFACTS[artefact]}"


def _run_folder(entry, root, name):
    if not entry.per_scale:
        return f"{root}/{name}"
    return f"{root}/{name}/${{item.scale}}" + ("/${item.hand}" if entry.per_hand else "")


def _header(what):
    return [
        f"# {what}, written by `python -m pipeline.dag` from pipeline/dag.py and the",
        "# objects of params.yaml: edit those, not this file. Paths are relative to the repository root.",
    ]


def dvc_file(name):
    """The text of ``dag/<name>/dvc.yaml``: the stage's ``code`` stage (the report's run)."""
    entry = stage(name)
    if entry is REPORT:
        lines = _header("Stage `report` of the DAG") + ["vars:", "  - ../../params.yaml", "stages:", "  report:"]
        lines += ["    wdir: ../..", "    cmd: python -m stages.report data report --log logs/report.mcap"]
        outs = ["report/report.md", "report/trials.parquet", "report/figures", "report/plots", "logs/report.mcap"]
        lines += ["    deps:"] + [f"      - {path}" for path in list(code_deps(name)) + ["data"]]
        lines += ["    params:"] + [f"      - {key}" for key in entry.params]
        lines += ["    outs:"] + [f"      - {path}" for path in outs]
        return "\n".join(lines + ["    metrics:", "      - report/metrics.json"]) + "\n"
    lines = _header(f"The code fingerprint of stage `{name}` (its runs: dag/{name}/<object>/dvc.yaml)")
    lines += [
        "stages:",
        "  code:",
        "    wdir: ../..",
        f"    cmd: python -m pipeline.dag --fingerprint {name} {fingerprint_path(name)}",
        "    deps:",
    ]
    lines += [f"      - {path}" for path in code_deps(name) + ("pipeline/dag.py",)]
    lines += ["    outs:", f"      - {fingerprint_path(name)}:", "          cache: false"]
    return "\n".join(lines) + "\n"


def object_dvc_file(name, object_name):
    """The text of ``dag/<name>/<object_name>/dvc.yaml``: stage ``name``'s runs of one object."""
    entry = stage(name)
    lines = _header(f"Stage `{name}` of object `{object_name}`")
    lines += ["vars:", "  - ../../../params.yaml", "stages:", f"  {name}:"]
    if entry.per_scale:
        lines += ["    matrix:", "      scale: ${scales}"] + (
            ["      hand: ${candidates.hands}"] if entry.per_hand else []
        )
    scale = "${item.scale}" if entry.per_scale else "${scales[0]}"
    logs, data = _run_folder(entry, "logs", object_name), _run_folder(entry, "data", object_name)
    item = {"object": object_name, "scale": scale, "hand": "${item.hand}"}
    inputs = [_path(artefact, object_name, scale) for artefact in entry.inputs + entry.recorded]
    outs = [_path(artefact, object_name, scale) for artefact in entry.outputs]
    argv = (
        inputs
        + [item[arg] for arg in entry.args]
        + outs
        + [f"--timing {data}/timing/{name}.json", f"--log {logs}/{name}.mcap"]
    )
    outs += [f"{data}/timing/{name}.json", f"{logs}/{name}.mcap"]
    if entry.recording:
        argv.append(f"--rrd {logs}/{entry.recording} --recording-id {object_name}-{scale}")
        outs.append(f"{logs}/{entry.recording}")
    lines += ["    wdir: ../../..", "    cmd: >-", f"      python -m stages.{name}"] + [f"      {arg}" for arg in argv]
    deps = [fingerprint_path(name)] + inputs
    lines += ["    deps:"] + [f"      - {path}" for path in deps]
    params = [key.replace("${item.object}", object_name) for key in entry.params]
    lines += ["    params:"] + [f"      - {key}" for key in params]
    lines += ["    outs:"] + [f"      - {path}" for path in outs]
    return "\n".join(lines) + "\n"


def stage_file(name):
    """Repository-relative path of stage ``name``'s own file (its ``code`` stage; the report)."""
    return f"dag/{name}/dvc.yaml"


def object_stage_file(name, object_name):
    """Repository-relative path of stage ``name``'s file for object ``object_name``."""
    return f"dag/{name}/{object_name}/dvc.yaml"


def stage_files(objects):
    """``{repository-relative path: text}`` of every stage file for the object names ``objects``."""
    files = {stage_file(entry.name): dvc_file(entry.name) for entry in STAGES + (REPORT,)}
    for entry in STAGES:
        files |= {object_stage_file(entry.name, name): object_dvc_file(entry.name, name) for name in objects}
    return files


def write_dvc_files(root=ROOT, *, check=False):
    """Write every stage file under ``root`` for the objects of ``root/params.yaml`` and remove the
    folders (stage file and lock) of objects no longer listed; with ``check``, change nothing and
    return the paths that differ (missing and no longer listed files included)."""
    from .params import load_params

    root = Path(root)
    files = stage_files(load_params(root / "params.yaml").objects)
    stale = [
        root / path for path, text in files.items() if not (root / path).is_file() or (root / path).read_text() != text
    ]
    gone = [path for path in sorted(root.glob(object_stage_file("*", "*"))) if str(path.relative_to(root)) not in files]
    if not check:
        for path in stale:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(files[str(path.relative_to(root))])
        for path in gone:
            for leftover in (path, path.with_name("dvc.lock")):
                leftover.unlink(missing_ok=True)
            if not any(path.parent.iterdir()):
                path.parent.rmdir()
    return stale + gone


def main(argv=None):
    import argparse
    import sys

    parser = argparse.ArgumentParser(prog="python -m pipeline.dag", description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="write nothing; exit 1 if a file is out of date")
    parser.add_argument(
        "--fingerprint", nargs=2, metavar=("STAGE", "OUT"), help="write STAGE's code fingerprint to OUT (DVC runs it)"
    )
    args = parser.parse_args(argv)
    if args.fingerprint:
        write_fingerprint(stage(args.fingerprint[0]).name, args.fingerprint[1])
        return
    stale = write_dvc_files(check=args.check)
    for path in stale:
        done = "removed" if not path.exists() else "wrote"
        print(f"{'out of date' if args.check else done}: {path.relative_to(ROOT)}")
    if args.check and stale:
        print("run `python -m pipeline.dag` to rewrite them", file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()

"""Command line: ``medial-grasp {plan,batch,bench,hands,objects,ablate,export,evaluate} ...`` (also ``python -m pipeline``;
``--help`` on each)."""

import argparse
import json
import sys
from pathlib import Path

from .errors import BadInputError, BadParamsError
from .params import Params, load_params
from .stage_io import PARAMS_FILE, one_line_errors, progress_bar

PARAMS_HELP = f"params file (default: {PARAMS_FILE} in the current folder if present, else built-in defaults)"


def _prog():
    """The name the user typed: the console script's, else ``python -m pipeline``."""
    return "medial-grasp" if Path(sys.argv[0]).name == "medial-grasp" else "python -m pipeline"


def _subcommand(commands, name, *, help, description, examples):
    """A subcommand whose --help shows ``description`` and its example command lines as written."""
    return commands.add_parser(
        name,
        help=help,
        description=description,
        epilog="example:\n" + "\n".join(f"  {line}" for line in examples),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


@one_line_errors
def main(argv=None):
    from .hands.spec import HANDS

    prog = _prog()
    parser = argparse.ArgumentParser(prog=prog, description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    plan = _subcommand(
        commands,
        "plan",
        help="run every stage on one mesh, outside DVC",
        description="Run every stage (sample ... candidates, then the grasp trials) on one object, outside DVC,\n"
        "and write each artefact and summary.json into --out. Params come from --params, else\n"
        f"{PARAMS_FILE} in the current folder if present, else the built-in defaults.",
        examples=[
            f"{prog} plan primitive:mug --out out/mug --spheres 20",
            f"{prog} plan my_part.stl --scale 0.001 --hand barrett --no-simulate --out out/part",
        ],
    )
    plan.add_argument("mesh", help="mesh or point-cloud file, primitive:NAME or pybullet:RELPATH")
    plan.add_argument("--out", required=True, help="folder for the artefacts and summary.json")
    plan.add_argument("--scale", type=float, default=1.0, help="factor on the coordinates (0.001 for mm; default: 1)")
    plan.add_argument("--seed", type=int, default=None, help="overrides the params seed (default: params seed)")
    plan.add_argument(
        "--hand",
        action="append",
        default=None,
        help="built-in hand name or hand spec .yaml/.toml (repeatable; default: params candidates.hands)",
    )
    plan.add_argument(
        "--spheres",
        type=int,
        default=None,
        help="random spheres per hand whose candidates are simulated (default: params simulate.spheres_per_object)",
    )
    plan.add_argument(
        "--baseline",
        type=int,
        default=None,
        help="surface-normal baseline trials per hand (default: params simulate.baseline_trials; "
        "-1 = as many as the MAT trials)",
    )
    plan.add_argument(
        "--workers", type=int, default=None, help="trial processes (default: params simulate.workers; 0 = every core)"
    )
    plan.add_argument(
        "--checks",
        type=int,
        default=None,
        help="trials checked (physics and robust force closure) per hand and planner "
        "(default: params checks.trials; -1 = every trial, 0 = none)",
    )
    plan.add_argument("--no-simulate", action="store_true", help="stop after the candidates")
    plan.add_argument(
        "--record", action="store_true", help="also write recording.rrd (open with `rerun`) and log.mcap into --out"
    )
    plan.add_argument("--params", default=None, help=PARAMS_HELP)
    batch = _subcommand(
        commands,
        "batch",
        help="run every stage on every mesh of a folder, on Ray (local or a cluster)",
        description="Plan every mesh under a folder (searched recursively) as one Ray task each, on an embedded\n"
        "local Ray or a cluster, into OUT/objects/*.parquet and OUT/trials/*.parquet. Objects done\n"
        "before with the same inputs are skipped, so an interrupted batch resumes.",
        examples=[
            f"{prog} batch pybullet:random_urdfs --scale 0.015 --hand barrett --out out/random --limit 10",
            f"{prog} batch meshes/ --hand armar3 --hand barrett --only 1,41,81 --out out/chosen",
        ],
    )
    batch.add_argument(
        "folder", help="folder of meshes (searched recursively), or pybullet:DIR, e.g. pybullet:random_urdfs"
    )
    batch.add_argument("--hand", action="append", required=True, help="built-in hand name or spec file (repeatable)")
    batch.add_argument("--out", required=True, help="output folder: objects/*.parquet and trials/*.parquet")
    batch.add_argument("--only", default=None, help="comma-separated file stems to plan (e.g. 000,007)")
    batch.add_argument("--limit", type=int, default=None, help="plan only the first N meshes (natural order)")
    batch.add_argument(
        "--address",
        default=None,
        help="join this Ray cluster (host:port; default $RAY_ADDRESS, else an embedded local Ray)",
    )
    batch.add_argument("--workers", type=int, default=None, help="CPUs of the embedded Ray (default: every core)")
    batch.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="factor on every mesh's coordinates (default: 1; 0.015 for pybullet:random_urdfs, as their URDFs)",
    )
    batch.add_argument("--seed", type=int, default=None, help="overrides the params seed (default: params seed)")
    batch.add_argument(
        "--spheres",
        type=int,
        default=None,
        help="random spheres per object and hand (default: params simulate.spheres_per_object)",
    )
    batch.add_argument(
        "--checks",
        type=int,
        default=None,
        help="trials checked (physics and robust force closure) per hand and planner "
        "(default: params checks.trials; -1 = every trial, 0 = none)",
    )
    batch.add_argument("--params", default=None, help=PARAMS_HELP)
    bench = _subcommand(
        commands,
        "bench",
        help="benchmark medial_axis + mat (vs voronoi_poles), classify + candidates, "
        "grasp trials and the cost of recording them",
        description="Time medial_axis + mat (against voronoi_poles), classify + candidates, the grasp trials,\n"
        "the cost of recording them and a small batch; prints one table each.",
        examples=[f"{prog} bench --only medial --sizes 20000 --repeats 1", f"{prog} bench --json bench.json"],
    )
    bench.add_argument("--json", default=None, help="also write the figures to this JSON file")
    bench.add_argument(
        "--sizes", default="20000,100000,200000", help="surface sample counts, comma-separated (default: %(default)s)"
    )
    bench.add_argument("--repeats", type=int, default=3, help="runs per case; the median is reported (default: 3)")
    bench.add_argument(
        "--trials",
        type=int,
        default=512,
        help="grasp trials per hand in the trial table (default: 512, one chunk of the engine's batch)",
    )
    bench.add_argument(
        "--reference-trials",
        type=int,
        default=60,
        help="of those, how many also run through the pybullet reference to compare outcomes "
        "(default: %(default)s; about 0.1-1 trial/s; 0: none)",
    )
    bench.add_argument(
        "--only",
        choices=("medial", "symmetry", "trials", "checks", "evaluate", "recording", "batch"),
        default=None,
        help="run one table (default: all)",
    )
    hands = _subcommand(
        commands,
        "hands",
        help="render the built-in hands, or export one as URDF + spec",
        description=f"Render the built-in hands, or export one as URDF + spec file.\n"
        f"built-in hands: {', '.join(HANDS)}",
        examples=[
            f"{prog} hands --render pictures",
            f"{prog} hands --export parallel_jaw myhand   # then: plan ... --hand myhand/parallel_jaw.yaml",
        ],
    )
    hands.add_argument("--render", metavar="DIR", help="write DIR/<hand>.png, open and closed on an object")
    hands.add_argument(
        "--export",
        nargs=2,
        metavar=("HAND", "DIR"),
        help="write DIR/HAND.urdf and DIR/HAND.yaml (a spec --hand accepts)",
    )
    objects = _subcommand(
        commands,
        "objects",
        help="params.yaml objects entries for every mesh in a folder",
        description="List every mesh under a folder (searched recursively) as params.yaml objects entries, after\n"
        "the checks of the sample stage (closed surface, units, finite coordinates...): a mesh that\n"
        "fails them is skipped with a warning. Nested files are named by their path, parts joined\n"
        "with '-'. --write replaces the objects section of a params file and keeps\n"
        "report.figure_objects naming objects of it.",
        examples=[
            f"{prog} objects meshes/ --scale 0.001 --write {PARAMS_FILE}   # then: dvc repro",
            f"{prog} objects benchmark/ --size 0.26 --only 1,41,81",
        ],
    )
    objects.add_argument("folder", help="folder of OBJ/STL/PLY/OFF/GLB meshes (searched recursively)")
    objects.add_argument("--scale", type=float, default=None, help="factor for every mesh (0.001 for mm; default: 1)")
    objects.add_argument(
        "--size", type=float, default=None, help="metres of each mesh's bounding-box diagonal, for unitless meshes"
    )
    objects.add_argument("--only", default=None, help="comma-separated file stems to keep (e.g. 1,41,81)")
    objects.add_argument("--prefix", default="", help="put before each object name")
    objects.add_argument(
        "--write",
        metavar="PARAMS",
        default=None,
        help="replace the objects section of this params file (else print the entries); "
        "its sample section and scales set the checks",
    )
    ablate = _subcommand(
        commands,
        "ablate",
        help="rerun one object's candidates switching one trial modelling choice at a time",
        description="Run the same candidates (the simulate stage's choice) through the grasp trials with the\n"
        "params as they are and once per variant that switches one modelling choice (retreat and\n"
        "approach steps, retreat only, contact tolerance, region merging, palm contacts, mu 1.0);\n"
        "print per hand, variant and planner the force-closure and physics success rates and their\n"
        "change from the default row, in points (see docs/ablation.md).",
        examples=[
            f"{prog} ablate primitive:mug --hand barrett --spheres 20 --physics-trials 20",
            f"{prog} ablate --from-data data/duck/1.0 --hand armar3 --hand barrett --spheres 40 --out duck.csv",
        ],
    )
    ablate.add_argument(
        "mesh", nargs="?", default=None, help="mesh file, primitive:NAME or pybullet:RELPATH (not with --from-data)"
    )
    ablate.add_argument(
        "--from-data",
        metavar="DIR",
        default=None,
        help="reuse a DVC run folder (e.g. data/duck/1.0: surface.npz, <hand>/candidates.parquet) "
        "instead of running the chain",
    )
    ablate.add_argument("--scale", type=float, default=1.0, help="factor on the coordinates (default: 1)")
    ablate.add_argument(
        "--hand",
        action="append",
        default=None,
        help="built-in hand name or hand spec file (repeatable; default: params candidates.hands)",
    )
    ablate.add_argument(
        "--spheres",
        type=int,
        default=None,
        help="random spheres per hand whose candidates are tried (default: params simulate.spheres_per_object)",
    )
    ablate.add_argument(
        "--cap", type=int, default=None, help="at most this many candidates per planner, a seeded sample (default: all)"
    )
    ablate.add_argument(
        "--physics-trials",
        type=int,
        default=50,
        help="physics checks per hand, variant and planner at most (0 = none, -1 = all; default: %(default)s)",
    )
    ablate.add_argument("--seed", type=int, default=None, help="overrides the params seed (default: params seed)")
    ablate.add_argument(
        "--workers", type=int, default=None, help="trial processes (default: params simulate.workers; 0 = every core)"
    )
    ablate.add_argument("--out", default=None, help="also write the table to this CSV file")
    ablate.add_argument("--params", default=None, help=PARAMS_HELP)
    export = _subcommand(
        commands,
        "export",
        help="write a run's grasps for a robot: ACRONYM-style HDF5 or JSON, one file per object, scale and hand",
        description="Export every grasp whose hand closed (force_closure, no_force_closure, no_contact) of a run,\n"
        "best first, with the hand's pose and joints in the object frame, its pre-grasp pose and the\n"
        "checks; beside each file the object mesh (.obj, times object/scale = the simulated mesh) and\n"
        "the hand's URDF. RUN_DIR: a `plan --out` folder, a `batch` output, the DVC data/ tree or\n"
        "the report/ folder (see docs/export.md).",
        examples=[
            f"{prog} export out/mug --format acronym --out grasps/mug",
            f"{prog} export data --format json --out grasps/all --standoff 0.08",
            f"{prog} export report --format acronym --out grasps/report   # meshes from ../data",
        ],
    )
    export.add_argument("run_dir", metavar="RUN_DIR", help="plan folder, batch output, data/ tree or report/ folder")
    export.add_argument("--format", required=True, choices=("acronym", "json"), help="acronym: HDF5 (.h5); json")
    export.add_argument("--out", required=True, help="folder for the files")
    export.add_argument(
        "--standoff",
        type=float,
        default=0.05,
        help="metres the pre-grasp pose stands back beyond the start of the trial's approach (default: %(default)s)",
    )
    export.add_argument(
        "--hand", action="append", default=[], help="spec .yaml/.toml of a hand that is not built in (repeatable)"
    )
    export.add_argument(
        "--data", default=None, help="the DVC data/ tree of a report/ folder (default: RUN_DIR/../data)"
    )
    export.add_argument(
        "--scale", type=float, default=1.0, help="a batch output's --scale (not recorded in it; default: %(default)s)"
    )
    evaluate = _subcommand(
        commands,
        "evaluate",
        help="label a grasp file (ACRONYM's HDF5, or an export) with this project's verdicts",
        description="Place the hand at each grasp's pose, open at the file's configuration, close it where it is\n"
        "(no retreat, no approach), and label it: outcome, force closure, epsilon, robust force closure and\n"
        "the lift-and-shake on pybullet and MuJoCo (from the closed pose and from the open hand closing on\n"
        "the free object), at the file's object mass and friction. Writes DIR/labels.parquet, the\n"
        "file with the labels under grasps/qualities/medial_grasp/, and, when the file has its own labels\n"
        "(grasps/qualities/flex/object_in_gripper), DIR/agreement.json (see docs/evaluate.md).",
        examples=[
            f"{prog} evaluate acronym/grasps/Mug_10f6e0_0.0002.h5 --mesh meshes/Mug/10f6e0.obj --sample 200 --out labels/mug",
            f"{prog} evaluate grasps/box-1.0-franka.h5 --out labels/box   # an export: its own mesh inside",
        ],
    )
    evaluate.add_argument("grasps", metavar="GRASPS", help="ACRONYM-layout .h5, or a medial-grasp export (.h5/.json)")
    evaluate.add_argument("--out", required=True, help="folder for labels.parquet, the labelled file, agreement.json")
    evaluate.add_argument(
        "--hand",
        default=None,
        help="built-in hand name or hand spec .yaml/.toml (default: the file's gripper/type; panda = franka)",
    )
    evaluate.add_argument("--mesh", default=None, help="the object's mesh, instead of the file's object/file")
    evaluate.add_argument("--sample", type=int, default=None, help="label a seeded sample of N grasps (default: all)")
    evaluate.add_argument("--seed", type=int, default=None, help="overrides the params seed (default: params seed)")
    evaluate.add_argument(
        "--engine",
        choices=("pybullet", "mujoco", "both"),
        default=None,
        help="the lift-and-shake engine(s) (default: params checks.engine)",
    )
    evaluate.add_argument(
        "--workers", type=int, default=None, help="processes (default: params simulate.workers; 0 = every core)"
    )
    evaluate.add_argument("--params", default=None, help=PARAMS_HELP)
    args = parser.parse_args(argv)
    if args.command == "evaluate":
        return _evaluate(args)
    if args.command == "export":
        return _export(args)
    if args.command == "objects":
        return _objects(args)
    if args.command == "plan":
        return _plan(args)
    if args.command == "batch":
        return _batch(args)
    if args.command == "ablate":
        return _ablate(args)
    if args.command == "hands":
        return _hands(args, hands)
    from .bench import run_bench

    run_bench(
        sizes=[int(size) for size in args.sizes.split(",")],
        repeats=args.repeats,
        json_path=args.json,
        trials=args.trials,
        reference_trials=args.reference_trials,
        only=args.only,
    )


def _hands(args, parser):
    if not (args.render or args.export):
        parser.error("give --render DIR and/or --export HAND DIR")
    if args.export:
        from .hands.spec import export_hand, get_hand

        print(f"wrote {export_hand(get_hand(args.export[0]), args.export[1])}")
    if args.render:
        from .outputs.render import render_builtin_hands

        for path in render_builtin_hands(args.render):
            print(f"wrote {path}")


def _objects(args):
    from .artefacts import atomic_write
    from .geometry.catalogue import entry_lines, figure_objects_following, folder_entries, replace_objects

    params_path = args.write or (PARAMS_FILE if Path(PARAMS_FILE).is_file() else None)
    entries = folder_entries(
        args.folder,
        prefix=args.prefix,
        scale=args.scale,
        size=args.size,
        only=args.only.split(",") if args.only else None,
        params_path=params_path,
        warn=lambda message: print(f"warning: {message}", file=sys.stderr),
    )
    if not args.write:
        print("\n".join(["objects:"] + [f"  {line}" for line in entry_lines(entries)]))
        return
    text = replace_objects(Path(args.write).read_text(), entries)
    text, figures = figure_objects_following(text, list(entries), source=args.write)
    atomic_write(args.write, lambda stream: stream.write(text.encode()))
    print(f"wrote {len(entries)} objects into {args.write} (report.figure_objects: {', '.join(figures)})")
    from .dag import ROOT, write_dvc_files

    if Path(args.write).resolve() == ROOT / "params.yaml":  # the DAG's own params: its objects' stage files
        changed = write_dvc_files()
        print(f"rewrote {len(changed)} stage files under {ROOT / 'dag'}: run `dvc repro`")
    else:
        print("with these objects in the project's params.yaml, run `python -m pipeline.dag`, then `dvc repro`")


def _command_params(args):
    """The params file of ``--params`` (or params.yaml here, else the defaults) with the
    command's ``--spheres`` / ``--baseline`` / ``--checks`` overrides."""
    import dataclasses

    params_path = args.params or (PARAMS_FILE if Path(PARAMS_FILE).is_file() else None)
    params = load_params(params_path) if params_path else Params()
    overrides = {
        key: value
        for key, value in (
            ("spheres_per_object", getattr(args, "spheres", None)),
            ("baseline_trials", getattr(args, "baseline", None)),
        )
        if value is not None
    }
    if overrides:
        params = dataclasses.replace(params, simulate=dataclasses.replace(params.simulate, **overrides))
    if getattr(args, "checks", None) is not None:
        params = dataclasses.replace(params, checks=dataclasses.replace(params.checks, trials=args.checks))
    return params


def _batch(args):
    from .batch import find_meshes, run_batch
    from .geometry.objects import select_meshes
    from .hands.spec import get_hand

    params = _command_params(args)
    for hand in args.hand:
        get_hand(hand)  # an unknown hand fails here, in one line, before Ray starts
    meshes = select_meshes(
        find_meshes(args.folder), folder=args.folder, only=args.only.split(",") if args.only else None, limit=args.limit
    )
    print(f"batch: {len(meshes)} meshes from {args.folder} -> {args.out}", file=sys.stderr)
    counts = run_batch(
        meshes,
        args.out,
        hands=args.hand,
        params=params,
        scale=args.scale,
        seed=args.seed,
        address=args.address,
        workers=args.workers,
        progress=lambda line: print(line, file=sys.stderr, flush=True),
    )
    print(
        f"batch {args.out}: {counts['ok']} ok, {counts['error']} bad meshes, {counts['failed']} failed, "
        f"{counts['skipped']} skipped (done before) in {counts['seconds']:.1f} s "
        f"(Ray start {counts['ray_start_s']:.1f} s); read: pd.read_parquet('{args.out}/objects')"
    )
    if counts["failed"]:
        raise SystemExit(1)  # failed objects run again next time; bad meshes (error rows) do not


def _plan(args):
    import warnings

    from .plan import run_chain, summary, warning_lines, write_plan

    params = _command_params(args)
    seed = params.seed if args.seed is None else args.seed
    hands = args.hand or list(params.candidates.hands)
    with progress_bar("simulate") as trial_progress, warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("default")  # each distinct warning once, as the DVC stages log them
        artefacts, timings = run_chain(
            args.mesh,
            params,
            scale=args.scale,
            seed=seed,
            hands=hands,
            simulate=not args.no_simulate,
            workers=args.workers,
            progress=lambda line: print(line, file=sys.stderr),
            trial_progress=trial_progress,
        )
    result = summary(
        artefacts, timings, source=args.mesh, scale=args.scale, seed=seed, hands=hands, warnings=warning_lines(caught)
    )
    for line in result["warnings"]:
        print(f"warning: {line}", file=sys.stderr)
    write_plan(args.out, artefacts, result)
    if args.record:
        from .hands.spec import get_hand
        from .outputs.trial_recording import record_chain

        name = Path(args.mesh.split(":")[-1]).stem or "object"
        record_chain(
            Path(args.out) / "recording.rrd",
            Path(args.out) / "log.mcap",
            artefacts,
            result,
            name=name,
            hands=[get_hand(hand) for hand in hands],
            settings=params.simulate,
        )
    brief = {**result["counts"], "classes": result["classes"], "candidates": result["candidates"]}
    if "trials" in result:
        brief.update({key: result[key] for key in ("trials", "force_closure_rate", "mean_epsilon", "outcomes")})
        brief["baseline_force_closure_rate"] = result["baseline"]["force_closure_rate"]
    print(json.dumps(brief))
    print(f"wrote {args.out}/summary.json")


def _export(args):
    import time

    from .hands.spec import load_hand
    from .outputs.export import export, find_runs

    start = time.perf_counter()
    hands = [load_hand(path) for path in args.hand]
    runs = find_runs(
        args.run_dir, data=args.data, scale=args.scale, warn=lambda line: print(f"warning: {line}", file=sys.stderr)
    )
    written = export(runs, args.out, fmt=args.format, standoff=args.standoff, hands=hands, progress=print)
    print(
        f"export {args.run_dir} -> {args.out}: {len(written)} files, {sum(count for _, count in written)} grasps "
        f"in {time.perf_counter() - start:.1f} s"
    )


def _evaluate(args):
    import time

    from .hands.spec import get_hand
    from .outputs.evaluate import agreement, agreement_text, label_grasps, sample_rows, verdict_settings, write_labels
    from .outputs.grasp_sets import DATASET_GRIPPER, read_grasp_set
    from .pool import default_workers

    start = time.perf_counter()
    params = _command_params(args)
    seed = params.seed if args.seed is None else args.seed
    out = Path(args.out)
    if out.resolve() == Path(args.grasps).resolve().parent:
        raise BadParamsError(
            f"evaluate: --out {out} is the folder of {args.grasps}; the labelled copy would replace it"
        )
    given = None
    if args.hand is not None:
        given = get_hand(args.hand)
    grasp_set = read_grasp_set(args.grasps, mesh=args.mesh, hands=[given] if given else [])
    if given is not None and given.name != grasp_set.hand.name:
        raise BadInputError(
            f"{args.grasps}: its grasps are for gripper/type {grasp_set.gripper!r} "
            f"({DATASET_GRIPPER.get(grasp_set.hand.name, grasp_set.hand.name)}), not hand {given.name!r}"
        )
    rows = sample_rows(len(grasp_set), args.sample, seed)
    settings, physics, robust = verdict_settings(grasp_set, params, engine=args.engine)
    workers = default_workers(params.simulate.workers if args.workers is None else args.workers)
    print(
        f"evaluate {args.grasps}: {len(rows)} of {len(grasp_set)} grasps, hand {grasp_set.hand.name} "
        f"(gripper/type {grasp_set.gripper}), mass {'file' if grasp_set.mass_kg else 'density rule'}, "
        f"mu {settings.mu:g}, {workers} workers"
    )
    with progress_bar("evaluate", unit="grasp") as progress:
        table = label_grasps(
            grasp_set,
            rows,
            settings=settings,
            physics=physics,
            robust=robust,
            seed=seed,
            vhacd_resolution=params.checks.vhacd_resolution,
            workers=workers,
            progress=progress,
        )
    found = agreement(table)
    meta = {
        "grasp_file": str(args.grasps),
        "mesh": grasp_set.mesh_file,
        "hand": grasp_set.hand.name,
        "gripper_type": grasp_set.gripper,
        "grasps": len(grasp_set),
        "labelled_grasps": len(rows),
        "seed": seed,
        "mu": settings.mu,
        "mass_kg": grasp_set.mass_kg,
        "mass_rule": "the file's object/mass"
        if grasp_set.mass_kg is not None
        else "mesh volume x checks.density_kg_m3, at most checks.payload_kg",
        "engines": sorted(physics),
        "robust_samples": robust["samples"],
    }
    if grasp_set.mass_kg is None:
        from .checks.physics import PhysicsSettings, object_mass

        checked = PhysicsSettings(**params.checks.physics_settings(settings.mu))
        meta["mass_kg"] = object_mass(checked, grasp_set.vertices, grasp_set.faces)
    written = write_labels(out, grasp_set, table, found, meta=meta)
    counts = table.outcome.value_counts().to_dict()
    print(f"outcomes: {', '.join(f'{name} {count}' for name, count in counts.items())}")
    if found is not None:
        for line in agreement_text(found):
            print(line)
    print(f"wrote {', '.join(map(str, written))} in {time.perf_counter() - start:.1f} s")


def _ablate(args):
    from .artefacts import atomic_write
    from .checks.ablate import ablate
    from .errors import BadParamsError
    from .hands.spec import get_hand
    from .pool import default_workers

    if (args.mesh is None) == (args.from_data is None):
        raise BadParamsError("ablate: give a MESH or --from-data DIR (one of them)")
    for name, value in (("--spheres", args.spheres), ("--cap", args.cap)):
        if value is not None and value < 1:
            raise BadParamsError(f"ablate: {name} must be >= 1, got {value}")
    if args.physics_trials < -1:
        raise BadParamsError(f"ablate: --physics-trials must be -1, 0 or a count, got {args.physics_trials}")
    params = _command_params(args)
    seed = params.seed if args.seed is None else args.seed
    names = args.hand or list(params.candidates.hands)
    hands = [get_hand(name) for name in names]  # an unknown hand fails here, in one line
    workers = default_workers(params.simulate.workers if args.workers is None else args.workers)
    source, surface, candidates, parts = _ablation_inputs(args, params, seed, names)
    print(f"ablate {source}: {', '.join(hand.name for hand in hands)}", file=sys.stderr)
    with progress_bar("ablate") as progress:
        table = ablate(
            surface,
            candidates,
            hands,
            params,
            seed=seed,
            cap=args.cap,
            physics_trials=args.physics_trials,
            workers=workers,
            parts=parts,
            progress=progress,
        )
    print(_ablation_text(table))
    if args.out:
        text = table.to_csv(index=False, float_format="%.4f").encode()
        atomic_write(args.out, lambda stream: stream.write(text))
        print(f"wrote {args.out}")


def _ablation_inputs(args, params, seed, hands):
    """(source text, SurfaceSamples, candidates table, convex parts or None) of the ablation:
    read from ``--from-data`` or computed by the chain up to the candidates."""
    if args.from_data:
        import pandas as pd

        from .artefacts import SurfaceSamples, read_table
        from .hands.spec import get_hand

        folder = Path(args.from_data)
        surface = SurfaceSamples.load(folder / "surface.npz")
        candidates = pd.concat(
            [read_table(folder / get_hand(hand).name / "candidates.parquet") for hand in hands], ignore_index=True
        )
        parts = None
        if (folder / "parts.npz").is_file():  # the decompose stage's convex parts
            from .checks.physics import ConvexParts

            parts = ConvexParts.load(folder / "parts.npz").parts
        return str(folder), surface, candidates, parts
    from .plan import run_chain

    artefacts, _ = run_chain(
        args.mesh,
        params,
        scale=args.scale,
        seed=seed,
        hands=hands,
        simulate=False,
        progress=lambda line: print(line, file=sys.stderr),
    )
    return args.mesh, artefacts["sample"], artefacts["candidates"], None


def _ablation_text(table):
    """The ablation table as aligned text: rates and changes in points."""
    if not len(table):
        return "no trials (no candidates for these hands)"
    shown = table[
        [
            "hand",
            "setting",
            "planner",
            "trials",
            "force_closure_pct",
            "force_closure_delta",
            "physics_checked",
            "physics_success_pct",
            "physics_success_delta",
        ]
    ].rename(
        columns={
            "force_closure_pct": "fc %",
            "force_closure_delta": "fc +-",
            "physics_checked": "checked",
            "physics_success_pct": "held %",
            "physics_success_delta": "held +-",
        }
    )
    return shown.to_string(index=False, float_format=lambda value: f"{value:.1f}", na_rep="-")


if __name__ == "__main__":
    main()

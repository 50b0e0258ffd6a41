"""``evaluate GRASPS --out DIR``: label a grasp file (ACRONYM's HDF5, or an export) with this
project's verdicts."""

from pathlib import Path

from ..errors import BadInputError, BadParamsError
from ..stage_io import progress_bar
from .options import add_params, add_seed, add_workers, command_params, command_workers, subcommand


def add(commands, prog):
    parser = subcommand(
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
    parser.add_argument("grasps", metavar="GRASPS", help="ACRONYM-layout .h5, or a medial-grasp export (.h5/.json)")
    parser.add_argument("--out", required=True, help="folder for labels.parquet, the labelled file, agreement.json")
    parser.add_argument(
        "--hand",
        default=None,
        help="built-in hand name or hand spec .yaml/.toml (default: the file's gripper/type; panda = franka)",
    )
    parser.add_argument("--mesh", default=None, help="the object's mesh, instead of the file's object/file")
    parser.add_argument("--sample", type=int, default=None, help="label a seeded sample of N grasps (default: all)")
    add_seed(parser)
    parser.add_argument(
        "--engine",
        choices=("pybullet", "mujoco", "both"),
        default=None,
        help="the lift-and-shake engine(s) (default: params checks.engine)",
    )
    add_workers(parser, "processes")
    add_params(parser)
    return parser


def run(args):
    import time

    from ..outputs.evaluate import agreement, agreement_text, label_grasps, sample_rows, verdict_settings, write_labels

    start = time.perf_counter()
    params, seed = command_params(args)
    out = Path(args.out)
    if out.resolve() == Path(args.grasps).resolve().parent:
        raise BadParamsError(
            f"evaluate: --out {out} is the folder of {args.grasps}; the labelled copy would replace it"
        )
    grasp_set = _grasp_set(args)
    rows = sample_rows(len(grasp_set), args.sample, seed)
    settings, physics, robust = verdict_settings(grasp_set, params, engine=args.engine)
    workers = command_workers(args, params)
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
    meta = _meta(args, grasp_set, rows, seed, settings, physics, robust, params)
    written = write_labels(out, grasp_set, table, found, meta=meta)
    counts = table.outcome.value_counts().to_dict()
    print(f"outcomes: {', '.join(f'{name} {count}' for name, count in counts.items())}")
    if found is not None:
        for line in agreement_text(found):
            print(line)
    print(f"wrote {', '.join(map(str, written))} in {time.perf_counter() - start:.1f} s")


def _grasp_set(args):
    """The grasp file read with ``--mesh`` and ``--hand``; a ``--hand`` that is not the file's gripper
    is refused."""
    from ..hands.spec import get_hand
    from ..outputs.grasp_sets import DATASET_GRIPPER, read_grasp_set

    given = None if args.hand is None else get_hand(args.hand)
    grasp_set = read_grasp_set(args.grasps, mesh=args.mesh, hands=[given] if given else [])
    if given is not None and given.name != grasp_set.hand.name:
        raise BadInputError(
            f"{args.grasps}: its grasps are for gripper/type {grasp_set.gripper!r} "
            f"({DATASET_GRIPPER.get(grasp_set.hand.name, grasp_set.hand.name)}), not hand {given.name!r}"
        )
    return grasp_set


def _meta(args, grasp_set, rows, seed, settings, physics, robust, params):
    """What agreement.json and the labelled file record of the run beside the labels."""
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
        from ..checks.physics import PhysicsSettings, object_mass

        checked = PhysicsSettings(**params.checks.physics_settings(settings.mu))
        meta["mass_kg"] = object_mass(checked, grasp_set.vertices, grasp_set.faces)
    return meta

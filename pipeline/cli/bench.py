"""``bench``: the project's timing tables (see :mod:`pipeline.bench`)."""

from .options import subcommand


def add(commands, prog):
    parser = subcommand(
        commands,
        "bench",
        help="benchmark medial_axis + mat (vs voronoi_poles), classify + candidates, "
        "grasp trials and the cost of recording them",
        description="Time medial_axis + mat (against voronoi_poles), classify + candidates, the grasp trials\n"
        "(one core and all cores), the checks, where a default simulate, decompose and check stage's time\n"
        "goes (on data/duck/1.0), the cost of recording, a small batch and how the last make run kept the\n"
        "cores busy (its stage logs); prints one table each.",
        examples=[f"{prog} bench --only medial --sizes 20000 --repeats 1", f"{prog} bench --json bench.json"],
    )
    parser.add_argument("--json", default=None, help="also write the figures to this JSON file")
    parser.add_argument(
        "--sizes", default="20000,100000,200000", help="surface sample counts, comma-separated (default: %(default)s)"
    )
    parser.add_argument("--repeats", type=int, default=3, help="runs per case; the median is reported (default: 3)")
    parser.add_argument(
        "--trials",
        type=int,
        default=512,
        help="grasp trials per hand in the trial table (default: 512, one chunk of the engine's batch)",
    )
    parser.add_argument(
        "--reference-trials",
        type=int,
        default=60,
        help="of those, how many also run through the pybullet reference to compare outcomes "
        "(default: %(default)s; about 0.1-1 trial/s; 0: none)",
    )
    parser.add_argument(
        "--only",
        choices=("medial", "symmetry", "trials", "checks", "stages", "evaluate", "recording", "batch", "run"),
        default=None,
        help="run one table (default: all)",
    )
    return parser


def run(args):
    from ..bench import run_bench
    from ..errors import BadParamsError

    sizes = args.sizes.split(",")
    if not all(size.strip().isdigit() and int(size) > 0 for size in sizes):
        raise BadParamsError(f"bench: --sizes must be positive sample counts, comma-separated, got {args.sizes!r}")
    for name, value, least in (
        ("--repeats", args.repeats, 1),
        ("--trials", args.trials, 1),
        ("--reference-trials", args.reference_trials, 0),
    ):
        if value < least:
            raise BadParamsError(f"bench: {name} must be >= {least}, got {value}")
    run_bench(
        sizes=[int(size) for size in sizes],
        repeats=args.repeats,
        json_path=args.json,
        trials=args.trials,
        reference_trials=args.reference_trials,
        only=args.only,
    )

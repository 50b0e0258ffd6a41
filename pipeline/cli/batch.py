"""``batch FOLDER --hand H --out DIR``: every mesh of a folder, one Ray task each."""

from .options import (
    add_checks,
    add_params,
    add_seed,
    add_spheres,
    checked_workers,
    command_params,
    only_stems,
    stderr,
    subcommand,
)


def add(commands, prog):
    parser = subcommand(
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
    parser.add_argument(
        "folder", help="folder of meshes (searched recursively), or pybullet:DIR, e.g. pybullet:random_urdfs"
    )
    parser.add_argument("--hand", action="append", required=True, help="built-in hand name or spec file (repeatable)")
    parser.add_argument("--out", required=True, help="output folder: objects/*.parquet and trials/*.parquet")
    parser.add_argument("--only", default=None, help="comma-separated file stems to plan (e.g. 000,007)")
    parser.add_argument("--limit", type=int, default=None, help="plan only the first N meshes (natural order)")
    parser.add_argument(
        "--address",
        default=None,
        help="join this Ray cluster (host:port; default $RAY_ADDRESS, else an embedded local Ray)",
    )
    parser.add_argument("--workers", type=int, default=None, help="CPUs of the embedded Ray (default: every core)")
    parser.add_argument(
        "--scale",
        type=float,
        default=1.0,
        help="factor on every mesh's coordinates (default: 1; 0.015 for pybullet:random_urdfs, as their URDFs)",
    )
    add_seed(parser)
    add_spheres(parser, "object and hand")
    add_checks(parser)
    add_params(parser)
    return parser


def run(args):
    from ..batch import find_meshes, run_batch
    from ..geometry.objects import select_meshes
    from ..hands.spec import get_hand

    params, _ = command_params(args)
    workers = checked_workers(args.workers)
    for hand in args.hand:
        get_hand(hand)  # an unknown hand fails here, in one line, before Ray starts
    meshes = select_meshes(find_meshes(args.folder), folder=args.folder, only=only_stems(args), limit=args.limit)
    stderr(f"batch: {len(meshes)} meshes from {args.folder} -> {args.out}")
    counts = run_batch(
        meshes,
        args.out,
        hands=args.hand,
        params=params,
        scale=args.scale,
        seed=args.seed,
        address=args.address,
        workers=workers,
        progress=stderr,
    )
    print(
        f"batch {args.out}: {counts['ok']} ok, {counts['error']} bad meshes, {counts['failed']} failed, "
        f"{counts['skipped']} skipped (done before) in {counts['seconds']:.1f} s "
        f"(Ray start {counts['ray_start_s']:.1f} s); read: pd.read_parquet('{args.out}/objects')"
    )
    if counts["failed"]:
        raise SystemExit(1)  # failed objects run again next time; bad meshes (error rows) do not

"""``export RUN_DIR --format acronym|json --out DIR``: a run's grasps for a robot."""

from .options import stderr, subcommand


def add(commands, prog):
    parser = subcommand(
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
    parser.add_argument("run_dir", metavar="RUN_DIR", help="plan folder, batch output, data/ tree or report/ folder")
    parser.add_argument("--format", required=True, choices=("acronym", "json"), help="acronym: HDF5 (.h5); json")
    parser.add_argument("--out", required=True, help="folder for the files")
    parser.add_argument(
        "--standoff",
        type=float,
        default=0.05,
        help="metres the pre-grasp pose stands back beyond the start of the trial's approach (default: %(default)s)",
    )
    parser.add_argument(
        "--hand", action="append", default=[], help="spec .yaml/.toml of a hand that is not built in (repeatable)"
    )
    parser.add_argument(
        "--data", default=None, help="the DVC data/ tree of a report/ folder (default: RUN_DIR/../data)"
    )
    parser.add_argument(
        "--scale", type=float, default=1.0, help="a batch output's --scale (not recorded in it; default: %(default)s)"
    )
    return parser


def run(args):
    import time

    from ..hands.spec import load_hand
    from ..outputs.export import export
    from ..outputs.export_runs import find_runs

    start = time.perf_counter()
    hands = [load_hand(path) for path in args.hand]
    runs = find_runs(args.run_dir, data=args.data, scale=args.scale, warn=lambda line: stderr(f"warning: {line}"))
    written = export(runs, args.out, fmt=args.format, standoff=args.standoff, hands=hands, progress=print)
    print(
        f"export {args.run_dir} -> {args.out}: {len(written)} files, {sum(count for _, count in written)} grasps "
        f"in {time.perf_counter() - start:.1f} s"
    )

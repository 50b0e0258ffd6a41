"""``ablate MESH``: the same candidates through the trials, one modelling choice switched at a time."""

from pathlib import Path

from ..errors import BadParamsError
from ..stage_io import progress_bar
from .options import (
    add_hands,
    add_params,
    add_seed,
    add_spheres,
    add_workers,
    command_params,
    command_workers,
    stderr,
    subcommand,
)

SHOWN_COLUMNS = {
    "hand": "hand",
    "setting": "setting",
    "planner": "planner",
    "trials": "trials",
    "force_closure_pct": "fc %",
    "force_closure_delta": "fc +-",
    "physics_checked": "checked",
    "physics_success_pct": "held %",
    "physics_success_delta": "held +-",
}


def add(commands, prog):
    parser = subcommand(
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
    parser.add_argument(
        "mesh", nargs="?", default=None, help="mesh file, primitive:NAME or pybullet:RELPATH (not with --from-data)"
    )
    parser.add_argument(
        "--from-data",
        metavar="DIR",
        default=None,
        help="reuse a DVC run folder (e.g. data/duck/1.0: surface.npz, <hand>/candidates.parquet; "
        "the object's data/duck/parts.npz, scaled to the folder's scale) instead of running the chain",
    )
    parser.add_argument("--scale", type=float, default=1.0, help="factor on the coordinates (default: 1)")
    add_hands(parser)
    add_spheres(parser, "hand whose candidates are tried")
    parser.add_argument(
        "--cap", type=int, default=None, help="at most this many candidates per planner, a seeded sample (default: all)"
    )
    parser.add_argument(
        "--physics-trials",
        type=int,
        default=50,
        help="physics checks per hand, variant and planner at most (0 = none, -1 = all; default: %(default)s)",
    )
    add_seed(parser)
    add_workers(parser)
    parser.add_argument("--out", default=None, help="also write the table to this CSV file")
    add_params(parser)
    return parser


def run(args):
    from ..artefacts import atomic_write
    from ..checks.ablate import ablate
    from ..hands.spec import get_hand

    if (args.mesh is None) == (args.from_data is None):
        raise BadParamsError("ablate: give a MESH or --from-data DIR (one of them)")
    for name, value in (("--spheres", args.spheres), ("--cap", args.cap)):
        if value is not None and value < 1:
            raise BadParamsError(f"ablate: {name} must be >= 1, got {value}")
    if args.physics_trials < -1:
        raise BadParamsError(f"ablate: --physics-trials must be -1, 0 or a count, got {args.physics_trials}")
    params, seed = command_params(args)
    names = args.hand or list(params.candidates.hands)
    hands = [get_hand(name) for name in names]  # an unknown hand fails here, in one line
    workers = command_workers(args, params)
    source, surface, candidates, parts = _inputs(args, params, seed, names)
    stderr(f"ablate {source}: {', '.join(hand.name for hand in hands)}")
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
    print(ablation_text(table))
    if args.out:
        text = table.to_csv(index=False, float_format="%.4f").encode()
        atomic_write(args.out, lambda stream: stream.write(text))
        print(f"wrote {args.out}")


def _inputs(args, params, seed, hands):
    """(source text, SurfaceSamples, candidates table, convex parts or None) of the ablation:
    read from ``--from-data`` or computed by the chain up to the candidates."""
    if args.from_data:
        import pandas as pd

        from ..artefacts import SurfaceSamples, read_table
        from ..hands.spec import get_hand

        folder = Path(args.from_data)
        surface = SurfaceSamples.load(folder / "surface.npz")
        candidates = pd.concat(
            [read_table(folder / get_hand(hand).name / "candidates.parquet") for hand in hands], ignore_index=True
        )
        parts = None
        if (folder.parent / "parts.npz").is_file():  # the decompose stage's convex parts, of the object
            from ..checks.physics import ConvexParts
            from ..errors import BadInputError

            try:
                scale = float(folder.name)
            except ValueError:
                raise BadInputError(f"{folder}: not a run folder data/<object>/<scale>") from None
            parts = ConvexParts.load(folder.parent / "parts.npz").at_scale(scale).parts
        return str(folder), surface, candidates, parts
    from ..plan import run_chain

    artefacts, _ = run_chain(
        args.mesh, params, scale=args.scale, seed=seed, hands=hands, simulate=False, progress=stderr
    )
    return args.mesh, artefacts["sample"], artefacts["candidates"], None


def ablation_text(table):
    """The ablation table as aligned text: rates and changes in points."""
    if not len(table):
        return "no trials (no candidates for these hands)"
    shown = table[list(SHOWN_COLUMNS)].rename(columns=SHOWN_COLUMNS)
    return shown.to_string(index=False, float_format=lambda value: f"{value:.1f}", na_rep="-")

"""``plan MESH --out DIR``: every stage on one mesh, outside DVC."""

import json
import sys
from pathlib import Path

from ..stage_io import PARAMS_FILE, progress_bar
from .options import (
    add_checks,
    add_hands,
    add_params,
    add_seed,
    add_spheres,
    add_workers,
    checked_workers,
    command_params,
    stderr,
    subcommand,
)


def add(commands, prog):
    parser = subcommand(
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
    parser.add_argument("mesh", help="mesh or point-cloud file, primitive:NAME or pybullet:RELPATH")
    parser.add_argument("--out", required=True, help="folder for the artefacts and summary.json")
    parser.add_argument("--scale", type=float, default=1.0, help="factor on the coordinates (0.001 for mm; default: 1)")
    add_seed(parser)
    add_hands(parser)
    add_spheres(parser, "hand whose candidates are simulated")
    parser.add_argument(
        "--baseline",
        type=int,
        default=None,
        help="surface-normal baseline trials per hand (default: params simulate.baseline_trials; "
        "-1 = as many as the MAT trials)",
    )
    add_workers(parser)
    add_checks(parser)
    parser.add_argument("--no-simulate", action="store_true", help="stop after the candidates")
    parser.add_argument(
        "--record", action="store_true", help="also write recording.rrd (open with `rerun`) and log.mcap into --out"
    )
    add_params(parser)
    return parser


def run(args):
    import warnings

    from ..plan import run_chain, summary, warning_lines, write_plan

    params, seed = command_params(args)
    workers = checked_workers(args.workers)
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
            workers=workers,
            progress=stderr,
            trial_progress=trial_progress,
        )
    result = summary(
        artefacts, timings, source=args.mesh, scale=args.scale, seed=seed, hands=hands, warnings=warning_lines(caught)
    )
    for line in result["warnings"]:
        print(f"warning: {line}", file=sys.stderr)
    write_plan(args.out, artefacts, result)
    if args.record:
        from ..hands.spec import get_hand
        from ..outputs.trial_recording import record_chain

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

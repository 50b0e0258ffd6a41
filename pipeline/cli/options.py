"""What several subcommands share: the subparser with examples, the params/seed/workers/hand/spheres/
checks options, and the params a command runs with."""

import argparse
import dataclasses
import sys
from pathlib import Path

from ..errors import BadParamsError
from ..params import Params, load_params
from ..stage_io import PARAMS_FILE

PARAMS_HELP = f"params file (default: {PARAMS_FILE} in the current folder if present, else built-in defaults)"


def prog():
    """The name the user typed: the console script's, else ``python -m pipeline``."""
    return "medial-grasp" if Path(sys.argv[0]).name == "medial-grasp" else "python -m pipeline"


def subcommand(commands, name, *, help, description, examples):
    """A subcommand whose --help shows ``description`` and its example command lines as written."""
    return commands.add_parser(
        name,
        help=help,
        description=description,
        epilog="example:\n" + "\n".join(f"  {line}" for line in examples),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def add_params(parser):
    parser.add_argument("--params", default=None, help=PARAMS_HELP)


def add_seed(parser):
    parser.add_argument("--seed", type=int, default=None, help="overrides the params seed (default: params seed)")


def add_workers(parser, what="trial processes"):
    parser.add_argument(
        "--workers", type=int, default=None, help=f"{what} (default: params simulate.workers; 0 = every core)"
    )


def add_hands(parser):
    """``--hand``, repeatable, defaulting to the params' candidates.hands."""
    parser.add_argument(
        "--hand",
        action="append",
        default=None,
        help="built-in hand name or hand spec .yaml/.toml (repeatable; default: params candidates.hands)",
    )


def add_spheres(parser, per):
    """``--spheres``: random spheres ``per`` (words such as "hand whose candidates are simulated")."""
    parser.add_argument(
        "--spheres",
        type=int,
        default=None,
        help=f"random spheres per {per} (default: params simulate.spheres_per_object)",
    )


def add_checks(parser):
    parser.add_argument(
        "--checks",
        type=int,
        default=None,
        help="trials checked (physics and robust force closure) per hand and planner "
        "(default: params checks.trials; -1 = every trial, 0 = none)",
    )


def command_params(args):
    """(Params, seed) of a command: ``--params`` (or params.yaml here, else the defaults) with its
    ``--spheres`` / ``--baseline`` / ``--checks`` overrides, and ``--seed`` else the params seed."""
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
    seed = getattr(args, "seed", None)
    return params, params.seed if seed is None else seed


def checked_workers(workers):
    """``--workers`` as given (None: not given), refused in one line if negative."""
    if workers is not None and workers < 0:
        raise BadParamsError(f"--workers must be >= 0 (0: every core), got {workers}")
    return workers


def command_workers(args, params):
    """Processes of a command: ``--workers``, else the params' simulate.workers (0 = every core)."""
    from ..pool import default_workers

    workers = checked_workers(args.workers)
    return default_workers(params.simulate.workers if workers is None else workers)


def only_stems(args):
    """``--only 1,41,81`` as a list of file stems, or None."""
    return args.only.split(",") if args.only else None


def stderr(line):
    """Progress and warnings go to stderr, so stdout keeps only results."""
    print(line, file=sys.stderr, flush=True)

"""Command line: ``medial-grasp {plan,batch,bench,hands,objects,ablate,export,evaluate} ...`` (also ``python -m pipeline``;
``--help`` on each)."""

import argparse

# one module per subcommand (its options and what it runs), options they share in cli/options.py

from .cli import COMMANDS
from .cli.options import prog
from .stage_io import one_line_errors


@one_line_errors
def main(argv=None):
    name = prog()
    parser = argparse.ArgumentParser(prog=name, description=__doc__)
    commands = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.add(commands, name).set_defaults(run=command.run)
    args = parser.parse_args(argv)
    return args.run(args)


if __name__ == "__main__":
    main()

"""Shared plumbing of the command line and the DVC stages: params, errors, exit codes."""

import argparse
import contextlib
import functools
import sys

from .errors import PipelineError
from .params import load_params

PARAMS_FILE = "params.yaml"


def one_line_errors(main):
    """Run ``main``; a PipelineError prints ``error: <message>`` on stderr and exits 2."""

    @functools.wraps(main)
    def wrapper(*args, **kwargs):
        try:
            return main(*args, **kwargs)
        except PipelineError as err:
            print(f"error: {err}", file=sys.stderr)
            raise SystemExit(2) from None
        except KeyboardInterrupt:
            print("error: interrupted", file=sys.stderr)
            raise SystemExit(130) from None

    return wrapper


def params(path=PARAMS_FILE):
    """The validated params file (see :mod:`pipeline.params`)."""
    return load_params(path)


def stage_args(description, *names, argv=None):
    """Parse a stage's positional arguments (input and output paths, from dvc.yaml's cmd)."""
    parser = argparse.ArgumentParser(description=description)
    for name in names:
        parser.add_argument(name)
    return parser.parse_args(argv)


@contextlib.contextmanager
def progress_bar(description, unit="trial"):
    """A ``progress(done, total)`` callable drawing a tqdm bar on stderr. The bar appears on the
    first call, so a command that fails before any work still prints a single error line."""
    from tqdm import tqdm

    bars = []

    def progress(done, total):
        if not bars:
            bars.append(tqdm(desc=description, unit=unit, total=total, file=sys.stderr, mininterval=1.0))
        bars[0].update(done)

    try:
        yield progress
    finally:
        for bar in bars:
            bar.close()

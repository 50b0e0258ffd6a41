"""Shared plumbing of the command line and the DVC stages: params, errors, exit codes."""

import argparse
import contextlib
import functools
import json
import os
import sys
import time

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
    """Parse a stage's positional arguments (input and output paths, from dvc.yaml's cmd) and
    its optional ``--timing PATH`` (see :func:`timed`)."""
    parser = argparse.ArgumentParser(description=description)
    for name in names:
        parser.add_argument(name)
    parser.add_argument("--timing", help="write the stage's wall time here (JSON) when it succeeds")
    return parser.parse_args(argv)


@contextlib.contextmanager
def timed(path, stage):
    """Time the block; on success write ``{"stage", "seconds", "process_seconds"}`` to ``path`` (if
    given), atomically: the block's wall time, and the process's since it started (imports
    included). The report's per-stage timings come from these files."""
    from .artefacts import atomic_write

    start = time.perf_counter()
    yield
    if path:
        seconds = time.perf_counter() - start
        process = max(_process_age(), seconds)
        record = {"stage": stage, "seconds": round(seconds, 3), "process_seconds": round(process, 3)}
        atomic_write(path, lambda stream: stream.write(json.dumps(record).encode()))


def _process_age():
    """Seconds since this process started (Linux: /proc), else 0."""
    try:
        with open("/proc/self/stat") as stat, open("/proc/uptime") as uptime:
            start_ticks = int(stat.read().rsplit(")", 1)[1].split()[19])  # field 22, starttime
            return float(uptime.read().split()[0]) - start_ticks / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return 0.0


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

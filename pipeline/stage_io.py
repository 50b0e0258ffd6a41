"""The DVC stages' plumbing, shared with the command line: params, stage arguments, one-line
errors and exit codes, the stage run (atomic timing, MCAP log) and progress bars."""

import argparse
import contextlib
import functools
import os
import sys
import time
import warnings
from pathlib import Path

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
    """Parse a stage's positional arguments (input and output paths, from dvc.yaml's cmd) and its
    optional log paths: ``--timing T.json``, ``--log L.mcap``, ``--rrd R.rrd`` with
    ``--recording-id ID`` (see :func:`stage_run`)."""
    parser = argparse.ArgumentParser(description=description)
    for name in names:
        parser.add_argument(name)
    parser.add_argument("--timing", help="write the stage's wall time here (JSON) when it succeeds")
    parser.add_argument("--log", help="write the stage's MCAP log here (params, hashes, counts, timings, warnings)")
    parser.add_argument("--rrd", help="write the stage's rerun recording here (empty if params `record` is false)")
    parser.add_argument(
        "--recording-id",
        default="object",
        help="rerun recording id and entity root: the .rrd files of one id merge in the viewer",
    )
    return parser.parse_args(argv)


class StageRun:
    """What a running stage reports: counts and warnings for its MCAP log; its rerun recording
    is written by :func:`pipeline.outputs.recording.record_stage` (see :func:`stage_run`)."""

    def __init__(self, stage, log, rrd, recording_id, record, outputs):
        self.stage, self.log, self.rrd, self.recording_id, self.enabled = stage, log, rrd, recording_id, record
        self.outputs = list(outputs)
        """Files the stage wrote, hashed into the log at the end (a stage may add to them)."""
        self.counts, self.record_seconds = {}, 0.0

    def count(self, **counts):
        """Add sizes of what the stage made (logged on ``/counts`` at the end)."""
        self.counts.update(counts)

    def warn(self, message):
        """A warning: on stderr now, and on the log's ``/warning`` topic."""
        print(f"warning: {message}", file=sys.stderr)
        if self.log:
            self.log.log("/warning", {"message": message})


@contextlib.contextmanager
def stage_run(args, stage, *, params=None, inputs=(), outputs=(), record=True):
    """Run a stage's block and log it; yields a :class:`StageRun`.

    On success, writes (each only if its path was given in ``args``) ``--timing`` as JSON
    ``{"stage", "seconds", "process_seconds", "record_seconds"}`` (the block's wall time, the
    process's since it started, imports included, and the part spent recording), and ``--log``:
    an MCAP log of the stage's start, ``params`` (dict), the path, size and SHA-256 of each of
    ``inputs`` and ``outputs``, the counts, warnings (Python warnings raised in the block
    included), the timing, the ``pipeline`` modules loaded (``/modules``) and the end. Every
    file is renamed into place only when complete; the timing and the log are written only when
    the whole block succeeds, so a failed stage leaves neither (its artefacts, each atomic, may
    be there: DVC reruns the stage). ``record`` (params ``record``) turns the recording off.
    """
    from .artefacts import atomic_write, json_bytes
    from .logbook import mcap_log

    start = time.perf_counter()
    with contextlib.ExitStack() as stack:
        log = stack.enter_context(mcap_log(args.log, stage)) if args.log else None
        run = StageRun(stage, log, args.rrd, args.recording_id, record, outputs)
        if log:
            log.log("/params", params or {})
            for path in inputs:
                log.artefact("input", path)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("default")
            yield run
        for warning in caught:
            run.warn(warning_line(warning))
        seconds = time.perf_counter() - start
        timing = {
            "stage": stage,
            "seconds": round(seconds, 3),
            "process_seconds": round(max(_process_age(), seconds), 3),
            "record_seconds": round(run.record_seconds, 3),
        }
        if log:
            for path in run.outputs:
                log.artefact("output", path)
            log.log("/counts", run.counts)
            log.log("/timing", timing)
            # the code that ran, to check against the stage's deps (pipeline.dag)
            log.log("/modules", {"modules": sorted(name for name in sys.modules if name.split(".")[0] == "pipeline")})
        if args.timing:
            atomic_write(args.timing, lambda stream: stream.write(json_bytes(timing)))


def warning_line(caught_warning):
    """One line for a warning caught with ``warnings.catch_warnings(record=True)``: its category,
    message and origin (file name and line)."""
    return (
        f"{caught_warning.category.__name__}: {caught_warning.message} "
        f"({Path(caught_warning.filename).name}:{caught_warning.lineno})"
    )


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
